"""run-images against pycolmap's own pipeline on the same photographs, side by side.

For every photo folder given, two inputs are built:

- ``named``: the folder as it is (its ``K.txt``, if any, is used by run-images; COLMAP reads
  EXIF focal lengths, as it always does),
- ``shuffled``: the same images copied under random names in a shuffled order, without
  ``K.txt`` and with the EXIF stripped (pixels re-encoded losslessly as PNG): names carry no
  order and the intrinsics are unknown, as with photos gathered from the internet.

On each input it runs

- ``colmap``: ``pycolmap.extract_features`` + ``match_exhaustive`` + ``incremental_mapping``
  with their defaults (the reference a COLMAP user knows),
- ``ours-before``: run-images ``--graph complete`` with the settings it had before the photo
  defaults (2000 features from OpenCV's SIFT at its own contrast threshold, plain SIFT, the
  detector's budget counted before merging, 1 px epipolar threshold),
- ``ours``: run-images ``--graph complete`` at its defaults,
- ``ours-knn4``: run-images ``--graph knn:4`` at its defaults (neighbours by image similarity).

and reports registered images, 3D points, mean track length, mean reprojection error and
wall time; for run-images the reconstruction after cleaning (``sparse/``), with the one before
cleaning beside it. Prints a markdown table and writes ``runs/bench-images/results.json``.

    python bench/images_vs_colmap.py                       # quick: the 640 px Sceaux copy
    python bench/images_vs_colmap.py DIR [DIR ...]         # e.g. the full-size photos

Measured on 2 cores: the quick default about 65 s; the 2832x2128 Sceaux photos (both inputs,
every method) about 25 min while the cores were shared, of which COLMAP's feature extraction
is the largest part.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DEFAULT_DATA = ROOT / "tests" / "data" / "sceaux_castle_640"
SUFFIXES = {".jpg", ".jpeg", ".png", ".tif", ".tiff"}


def shuffled_copy(src: Path, dst: Path, seed: int = 0) -> dict[str, str]:
    """Copy the images of ``src`` to ``dst`` under random names, no K.txt, no EXIF.

    Returns ``{new name: original name}``.
    """
    from PIL import Image

    files = sorted(p for p in src.iterdir() if p.suffix.lower() in SUFFIXES)
    rng = random.Random(seed)
    ids = rng.sample(range(10**7, 10**8), len(files))
    rng.shuffle(files)
    dst.mkdir(parents=True, exist_ok=True)
    mapping = {}
    for f, k in zip(files, ids, strict=True):
        name = f"{k}.png"
        with Image.open(f) as im:
            # a new image from the pixels only: no EXIF, no ICC, no orientation tag
            Image.frombytes(im.mode, im.size, im.tobytes()).save(dst / name)
        mapping[name] = f.name
    return mapping


def run_colmap(images: Path, work: Path) -> dict:
    import pycolmap

    work.mkdir(parents=True, exist_ok=True)
    db = work / "database.db"
    pycolmap.logging.minloglevel = 2
    t0 = time.perf_counter()
    pycolmap.extract_features(db, images)
    t1 = time.perf_counter()
    pycolmap.match_exhaustive(db)
    t2 = time.perf_counter()
    models = pycolmap.incremental_mapping(db, images, work / "sparse")
    t3 = time.perf_counter()
    with pycolmap.Database.open(db) as d:
        n_images = d.num_images()
        n_kp = [d.read_keypoints(im.image_id).shape[0] for im in d.read_all_images()]
    row = {"images": n_images, "features_mean": round(sum(n_kp) / max(len(n_kp), 1)),
           "time_s": round(t3 - t0, 1),
           "time_split_s": {"features": round(t1 - t0, 1), "matching": round(t2 - t1, 1),
                            "mapping": round(t3 - t2, 1)}}
    if not models:
        return {**row, "registered": 0, "points": 0, "track_length": 0.0, "reproj_px": 0.0}
    rec = max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D()))
    rec.update_point_3d_errors()
    return {**row, "registered": rec.num_reg_images(), "points": rec.num_points3D(),
            "track_length": round(rec.compute_mean_track_length(), 3),
            "reproj_px": round(rec.compute_mean_reprojection_error(), 3)}


def run_ours(images: Path, work: Path, graph: str, legacy: bool) -> dict:
    from pipeline.progress import StageTimer
    from pipeline.runs.images import ImagesConfig, run_images

    cfg = ImagesConfig(directory=str(images), graph=graph, out=str(work / "run"), rerun=False,
                       threads=-1)
    if legacy:
        cfg.max_features, cfg.contrast_threshold, cfg.rootsift = 2000, None, False
        cfg.threshold_px, cfg.budget_after_merge = 1.0, False
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the run's own report table
        out = run_images(cfg, StageTimer(verbose=False))
    dt = time.perf_counter() - t0
    report = json.loads((out / "report.json").read_text())
    after, before = report["triangulation"]["after"], report["triangulation"]["before"]
    return {"images": report["n_cameras"],
            "features_mean": round(sum(report["features_per_camera"]) / report["n_cameras"]),
            "registered": after["registered_images"], "points": after["points"],
            "track_length": after["mean_track_length"],
            "reproj_px": after["mean_reprojection_error"], "time_s": round(dt, 1),
            "time_split_s": {k: round(v, 1) for k, v in report["timings_s"].items()},
            "before_cleaning": {"registered": before["registered_images"],
                                "points": before["points"],
                                "track_length": before["mean_track_length"]},
            "links": report["before"]["links"], "links_kept": report["after"]["links"],
            "comm_edges": len(report["comm_edges"]), "flags": report.get("flags", [])}


METHODS = {
    "colmap": lambda images, work: run_colmap(images, work),
    "ours-before": lambda images, work: run_ours(images, work, "complete", legacy=True),
    "ours": lambda images, work: run_ours(images, work, "complete", legacy=False),
    "ours-knn4": lambda images, work: run_ours(images, work, "knn:4", legacy=False),
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="*", type=Path, default=[DEFAULT_DATA],
                    help=f"photo folders (default: {DEFAULT_DATA.relative_to(ROOT)})")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"comma-separated subset of {','.join(METHODS)}")
    ap.add_argument("--inputs", default="named,shuffled", help="named, shuffled or both")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench-images" / "results.json")
    args = ap.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    inputs = [i for i in args.inputs.split(",") if i]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-images-") as tmp:
        tmp = Path(tmp)
        for folder in args.folders:
            for kind in inputs:
                images = folder if kind == "named" else tmp / f"{folder.name}-shuffled"
                if kind == "shuffled" and not images.exists():
                    shuffled_copy(folder, images)
                for method in methods:
                    work = tmp / f"{folder.name}-{kind}-{method}"
                    print(f"== {folder.name} {kind} {method} ...", file=sys.stderr, flush=True)
                    try:
                        row = METHODS[method](images, work)
                    except Exception as exc:  # noqa: BLE001 - a failed run is a result too
                        row = {"error": f"{type(exc).__name__}: {exc}"}
                    rows.append({"data": folder.name, "input": kind, "method": method, **row})
                    print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
                    shutil.rmtree(work, ignore_errors=True)
    header = ("| data | input | method | registered | points | track length | reproj. px "
              "| time s | features/img |")
    lines = [header, "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['data']} | {r['input']} | {r['method']} | error: {r['error']} "
                         f"| | | | | |")
            continue
        lines.append(f"| {r['data']} | {r['input']} | {r['method']} | {r['registered']}/"
                     f"{r['images']} | {r['points']} | {r['track_length']:.2f} | "
                     f"{r['reproj_px']:.2f} | {r['time_s']} | {r['features_mean']} |")
    table = "\n".join(lines)
    print(table)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    import cv2
    import pycolmap

    payload = {"rows": rows, "table": table, "cores": os.cpu_count(),
               "python": platform.python_version(), "opencv": cv2.__version__,
               "pycolmap": pycolmap.__version__}
    tmp_out = args.out.with_suffix(".json.tmp")
    tmp_out.write_text(json.dumps(payload, indent=1))
    os.replace(tmp_out, args.out)
    print(f"saved {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
