"""run-images against pycolmap's own pipeline on the same photographs, side by side, and
where cleaning a COLMAP database helps, against exact truth.

Inputs (each folder given, plus the rendered ring scenes):

- ``named``: the folder as it is (its ``K.txt``, if any, is used by run-images; COLMAP reads
  EXIF focal lengths, as it always does),
- ``renamed``: the same images copied under random names in a shuffled order, without
  ``K.txt`` and with the EXIF stripped (pixels re-encoded losslessly as PNG): names carry no
  order and the intrinsics are unknown, as with photos gathered from the internet,
- ``ring-ABCD`` / ``ring-AABB``: :mod:`data_synth.symmetric` — a tower of repeated modules
  seen by a ring of 18 cameras (``--ring-cameras``: other counts, named ``ring-ABCD-30cams``),
  written as a photo folder with its truth (poses and depth); ``AABB``: two adjacent sides
  exact copies of each other.

Methods on each input:

- ``colmap``: ``pycolmap.extract_features`` + ``match_exhaustive`` + ``incremental_mapping``
  at their defaults (the reference a COLMAP user knows),
- ``colmap+clean-db``: the same database through ``clean-db`` (the distributed consistency
  stage, :mod:`pipeline.runs.clean_db`) between matching and mapping; its time is colmap's
  extraction and matching plus the cleaning and the mapping,
- ``colmap+clean-db+loops``: the same with ``clean-db --loop-check`` (image pairs whose
  relative rotation breaks the triangles of the view graph dropped first,
  :mod:`pipeline.matching.loops`); on the inputs with truth, which pairs it dropped,
  judged against it, and every database of these rows also mapped with the fixed seeds at
  15 pose inliers (``seeds_min15``: run-images' relaxed registration threshold,
  :data:`pipeline.colmap.mapping.RETRY_MIN_POSE_INLIERS`),
- ``colmap+clean-db+fusion``: the same with ``clean-db --fusion`` (the robust distributed
  fusion on the poses of a COLMAP mapping of the input cuts the observations voted out of
  their tracks); its time includes that mapping; its databases are also mapped at 15 pose
  inliers (``seeds_min15``),
- ``ours``: run-images ``--graph complete`` at its defaults (the reconstruction after
  cleaning, ``sparse/``; the one before cleaning beside it),
- ``ours-no-fusion``: the same with ``--no-fusion`` (the consistency stage's cuts only),
- ``ours-remap``: the same with ``--remap`` (the kept links mapped from scratch instead of on
  the poses of the reconstruction before cleaning),
- ``ours-knn4``: run-images ``--graph knn:4`` (neighbours by image similarity).

Columns: registered images, 3D points, mean track length, mean reprojection error, wall time,
and where the truth is known the camera rotation / position errors after a similarity
alignment and the wrong tracks (tracks joining true points more than 0.1 m apart,
:mod:`pipeline.evaluation.scene_truth`); there ``colmap`` and ``colmap+clean-db`` also map
their two databases again with fixed seeds 0, 1, 2 (COLMAP's default seed is random, and one
mapping of a scene of repeated structure may fold where the next does not). Prints a markdown table and writes
``runs/bench-images/results.json``.

    python bench/images_vs_colmap.py                       # Sceaux (full size), Graffiti, rings
    python bench/images_vs_colmap.py --quick               # the 640 px Sceaux copy and one ring
    python bench/images_vs_colmap.py DIR [DIR ...]         # other photo folders (plus the rings)

Times are wall-clock seconds on this machine with its 2 cores shared with other work: compare
rows of one run only (modules are imported before any clock starts, :data:`WARM_IMPORTS`);
``cpu_s`` beside them is the CPU time of the run (this process and its
forked feature workers), which other work on the cores changes less.
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

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402
from multiway import SHARED_DATA  # noqa: E402

from pipeline.errors import one_line_errors  # noqa: E402

QUICK_DATA = ROOT / "tests" / "data" / "sceaux_castle_640"
DEFAULT_DATA = [SHARED_DATA / "sceaux_castle", SHARED_DATA / "graffiti"]
#: folders only measured as named (renaming is measured on the first)
NAMED_ONLY = {"graffiti"}
RING_CAMERAS = 18
#: fixed mapping seeds of the inputs with truth (``colmap`` and ``colmap+clean-db``)
SEEDS = (0, 1, 2)
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


def cpu_s() -> float:
    """CPU seconds (user + system) of this process and its finished children so far: with
    other work on the cores, wall time measures the share the run got, CPU time the work it
    did (forked feature workers are children, COLMAP's threads are this process)."""
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(
        resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _judge(rec, truth) -> dict:
    """Pose errors and wrong tracks of a reconstruction against the truth (or nothing)."""
    if truth is None or rec is None:
        return {}
    from pipeline import colmap
    from pipeline.evaluation.scene_truth import pose_errors, wrong_tracks

    poses = {n: (R, t) for n, (R, t, _) in colmap.registered_poses(rec).items()}
    pe = pose_errors(poses, truth)
    wt = wrong_tracks(colmap.model_tracks(rec), truth)
    return {"rotation_deg": pe["rotation_deg"], "position_m": pe["position_m"],
            "wrong_tracks": wt["wrong"], "judged_tracks": wt["judged"]}


def wrong_link_anatomy(db: Path, cleaned: Path, truth) -> dict:
    """Where the wrong verified matches of a COLMAP database sit, and what clean-db cut.

    ``wrong`` links join different true points. The consistency stage can only see a wrong
    link inside a *conflictive* set (one holding two features of one image, Aragüés et al.
    Def. 2.4); in a set of two features (a match no third image confirms) or in a larger
    conflict-free set it is invisible to it.
    """
    from pipeline import colmap
    from pipeline.association import AssociationGraph
    from pipeline.evaluation.scene_truth import wrong_links

    before, after = colmap.read_database(db), colmap.read_database(cleaned)
    L = before.links
    wrong, judged = wrong_links(before.names, before.keypoints, L, truth)
    m = before.features_per_camera
    graph = AssociationGraph(m, L)
    labels = graph.components()
    cam = np.repeat(np.arange(len(m)), m)
    key = np.unique(labels * len(m) + cam, return_counts=True)
    conflictive = np.unique(key[0][key[1] > 1] // len(m))
    g = graph.offsets[L.cam_i] + L.feat_i
    in_conflict = np.isin(labels[g], conflictive)
    size = np.bincount(labels)[labels[g]]
    wrong_after, _ = wrong_links(after.names, after.keypoints, after.links, truth)
    return {"links": int(len(L)), "judged": int(judged.sum()), "wrong": int(wrong.sum()),
            "wrong_in_conflictive_sets": int((wrong & in_conflict).sum()),
            "wrong_in_two_feature_sets": int((wrong & (size == 2)).sum()),
            "wrong_in_larger_consistent_sets": int((wrong & (size > 2) & ~in_conflict).sum()),
            "links_in_conflictive_sets": int(in_conflict.sum()),
            "links_after_clean_db": int(len(after.links)),
            "wrong_after_clean_db": int(wrong_after.sum())}


def _model_row(models, truth) -> dict:
    if not models:
        return {"registered": 0, "points": 0, "track_length": 0.0, "reproj_px": 0.0}
    rec = max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D()))
    rec.update_point_3d_errors()
    return {"registered": rec.num_reg_images(), "points": rec.num_points3D(),
            "track_length": round(rec.compute_mean_track_length(), 3),
            "reproj_px": round(rec.compute_mean_reprojection_error(), 3), **_judge(rec, truth)}


#: the clean-db variants of the colmap rows: method -> (database name, clean_database options)
CLEANINGS = {"colmap+clean-db": ("cleaned", {}),
             "colmap+clean-db+loops": ("cleaned-loops", {"loop_tol_deg": "default"}),
             "colmap+clean-db+fusion": ("cleaned-fusion", {"fusion": True})}


def run_colmap(images: Path, work: Path, truth=None,
               cleanings=("colmap+clean-db",), one_camera: bool = False) -> list[dict]:
    """The ``colmap`` row and one row per clean-db variant of ``cleanings`` (keys of
    :data:`CLEANINGS`, in that order): one extraction and matching, one mapping per
    database. ``one_camera``: every image shares one camera (``CameraMode.SINGLE``; pycolmap's
    default gives each image its own), as ``run-images`` gives images of one file size."""
    import pycolmap

    from pipeline.matching.loops import DEFAULT_LOOP_TOL_DEG
    from pipeline.runs.clean_db import clean_database

    work.mkdir(parents=True, exist_ok=True)
    db = work / "database.db"
    pycolmap.logging.minloglevel = 2
    c0, t0 = cpu_s(), time.perf_counter()
    pycolmap.extract_features(db, images, camera_mode=pycolmap.CameraMode.SINGLE
                              if one_camera else pycolmap.CameraMode.AUTO)
    t1 = time.perf_counter()
    pycolmap.match_exhaustive(db)
    t2 = time.perf_counter()
    models = pycolmap.incremental_mapping(db, images, work / "sparse")
    t3, c3 = time.perf_counter(), cpu_s()
    with pycolmap.Database.open(db) as d:
        n_images = d.num_images()
        n_kp = [d.read_keypoints(im.image_id).shape[0] for im in d.read_all_images()]
    base = {"images": n_images, "features_mean": round(sum(n_kp) / max(len(n_kp), 1))}
    colmap_row = {**base, "time_s": round(t3 - t0, 1), "cpu_s": round(c3 - c0, 1),
                  "time_split_s": {"features": round(t1 - t0, 1), "matching": round(t2 - t1, 1),
                                   "mapping": round(t3 - t2, 1)},
                  **_model_row(models, truth)}
    rows, paths, relaxed = [colmap_row], [db], [False]
    for method in cleanings:
        name, opts = CLEANINGS[method]
        opts = {k: DEFAULT_LOOP_TOL_DEG if v == "default" else v for k, v in opts.items()}
        tol = opts.get("loop_tol_deg")
        t4 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):
            cleaned = clean_database(db, work / f"{name}.db", rerun=False, **opts)
        t5 = time.perf_counter()
        models2 = pycolmap.incremental_mapping(work / f"{name}.db", images,
                                               work / f"sparse-{name}")
        t6 = time.perf_counter()
        row = {**base, "time_s": round((t2 - t0) + (t6 - t4), 1),
               "time_split_s": {"features": round(t1 - t0, 1), "matching": round(t2 - t1, 1),
                                "clean-db": round(t5 - t4, 1), "mapping": round(t6 - t5, 1)},
               "links": cleaned.links, "links_cut": cleaned.cut,
               **({"loop_check": cleaned.loop_check} if cleaned.loop_check else {}),
               **({"fusion": {k: v for k, v in cleaned.fusion.items() if k in (
                   "enabled", "cameras", "links_cut", "mapping", "sigma_px")}}
                  if cleaned.fusion else {}),
               **_model_row(models2, truth)}
        if truth is not None:
            row["wrong_links"] = wrong_link_anatomy(db, work / f"{name}.db", truth)
            if tol is not None:
                row["loop_pairs"] = loop_pair_anatomy(db, tol, truth)
        rows.append(row)
        paths.append(work / f"{name}.db")
        relaxed.append(method != "colmap+clean-db")
    if truth is not None:
        # COLMAP's mapping is not repeatable across runs (its default seed is random): the
        # same databases mapped again with fixed seeds separate cleaning from chance; with
        # the loop check, also at run-images' relaxed registration threshold (a pair-level
        # cut leaves the frontier images of the ring below COLMAP's 30 points)
        from pipeline.colmap.mapping import RETRY_MIN_POSE_INLIERS

        any_relaxed = any(relaxed)
        for row, path in zip(rows, paths, strict=True):
            for key, min_inliers in (("seeds", None),) + (
                    (("seeds_min15", RETRY_MIN_POSE_INLIERS),) if any_relaxed else ()):
                row[key] = []
                for seed in SEEDS:
                    options = pycolmap.IncrementalPipelineOptions()
                    options.random_seed = seed
                    if min_inliers is not None:
                        options.mapper.abs_pose_min_num_inliers = min_inliers
                    out = work / f"{key}{seed}-{path.stem}"
                    got = _model_row(pycolmap.incremental_mapping(path, images, out, options),
                                     truth)
                    row[key].append({"seed": seed, **got})
    return rows


def loop_pair_anatomy(db: Path, tol_deg: float, truth) -> dict:
    """What the loop check (``clean-db --loop-check``) drops, judged against the truth: a
    pair is *wrong* when most of its judged verified matches join different true points."""
    from pipeline import colmap
    from pipeline.evaluation.scene_truth import wrong_links
    from pipeline.matching.loops import loop_check

    c = colmap.read_database(db)
    try:
        n = len(c.names)
        pairs, rotations, inliers = colmap.relative_rotations(c)
        check = loop_check(n, pairs, rotations, inliers, tol_deg)
        wrong, judged = wrong_links(c.names, c.keypoints, c.links, truth)
        key = c.links.cam_i * n + c.links.cam_j
        pk = pairs[:, 0] * n + pairs[:, 1]
        n_wrong = np.array([wrong[key == k].sum() for k in pk])
        n_judged = np.array([judged[key == k].sum() for k in pk])
        bad = n_wrong * 2 > np.maximum(n_judged, 1)
        drop = check.inconsistent
    finally:
        c.close()
    return {"pairs": int(len(pairs)), "wrong_pairs": int(bad.sum()),
            "wrong_pairs_dropped": int((bad & drop).sum()),
            "right_pairs_dropped": int((~bad & drop).sum()),
            "wrong_matches_in_kept_pairs": int(n_wrong[~drop].sum()),
            "wrong_matches": int(n_wrong.sum())}


def run_ours(images: Path, work: Path, graph: str, truth=None, fusion: bool = True,
             remap: bool = False) -> dict:
    from pipeline import colmap
    from pipeline.progress import StageTimer
    from pipeline.runs.images import ImagesConfig, run_images

    cfg = ImagesConfig(directory=str(images), graph=graph, out=str(work / "run"), rerun=False,
                       threads=-1, fusion=fusion, remap=remap)
    c0, t0 = cpu_s(), time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the run's own report table
        out = run_images(cfg, StageTimer(verbose=False))
    dt, dc = time.perf_counter() - t0, cpu_s() - c0
    report = json.loads((out / "report.json").read_text())
    after, before = report["triangulation"]["after"], report["triangulation"]["before"]
    return {"images": report["n_cameras"],
            "features_mean": round(sum(report["features_per_camera"]) / report["n_cameras"]),
            "registered": after["registered_images"], "points": after["points"],
            # a model of no point: 0.0, as _model_row counts COLMAP's own runs
            "track_length": after["mean_track_length"] or 0.0,
            "reproj_px": after["mean_reprojection_error"] or 0.0, "time_s": round(dt, 1),
            "cpu_s": round(dc, 1),
            "time_split_s": {k: round(v, 1) for k, v in report["timings_s"].items()},
            "before_cleaning": {"registered": before["registered_images"],
                                "points": before["points"],
                                "track_length": before["mean_track_length"] or 0.0},
            "links": report["before"]["links"], "links_kept": report["after"]["links"],
            "comm_edges": len(report["comm_edges"]), "flags": report.get("flags", []),
            **_judge(colmap.read_model(out / "sparse"), truth)}


METHODS = ("colmap", "colmap-one-camera", "colmap+clean-db", "colmap+clean-db+loops",
           "colmap+clean-db+fusion", "ours", "ours-no-fusion", "ours-remap", "ours-knn4")
#: run-images variants: method -> (graph, fusion, remap)
OURS = {"ours": ("complete", True, False), "ours-no-fusion": ("complete", False, False),
        "ours-remap": ("complete", True, True), "ours-knn4": ("knn:4", True, False)}


def _fmt_err(r: dict) -> tuple[str, str, str]:
    if r.get("rotation_deg") is None:
        return ("", "", "") if "wrong_tracks" not in r else ("n/a", "n/a", "")
    return (f"{r['rotation_deg']['median']:.2f}", f"{r['position_m']['median']:.3f}",
            f"{r['wrong_tracks']}/{r['judged_tracks']}")


def _inputs(folders, kinds, tmp: Path, rings: list[str], ring_seeds=(0,),
            ring_cameras=(RING_CAMERAS,)):
    """``(data name, input kind, image folder, truth or None)`` for every measured input."""
    from data_synth.symmetric import write_ring_folder
    from pipeline.evaluation.scene_truth import read_truth

    for folder in folders:
        for kind in kinds:
            if kind == "renamed" and folder.name in NAMED_ONLY:
                continue
            images = folder if kind == "named" else tmp / f"{folder.name}-renamed"
            if kind == "renamed" and not images.exists():
                shuffled_copy(folder, images)
            yield folder.name, kind, images, None
    for cams in ring_cameras:
        for sides in rings:
            for seed in ring_seeds:
                name = f"ring-{sides}" + (f"-{cams}cams" if cams != RING_CAMERAS else "") + (
                    f"-seed{seed}" if seed else "")
                images = tmp / name
                write_ring_folder(images, n=cams, sides=sides, seed=seed)
                yield name, "named", images, read_truth(images)


#: modules run-images imports on first use (its command line loads lazily); imported before any
#: clock starts, as pycolmap is for the colmap rows
WARM_IMPORTS = ("cv2", "PIL.Image", "scipy.sparse.csgraph", "pycolmap", "pipeline.stages",
                "pipeline.runs.images", "pipeline.runs.transports.sim",
                "pipeline.runs.clean_db", "pipeline.consistency", "pipeline.consistency.engines",
                "pipeline.fusion.landmarks", "pipeline.evaluation.report",
                "pipeline.evaluation.flags", "pipeline.evaluation.truth",
                "pipeline.inputs.photos", "pipeline.inputs.linkscsv",
                "pipeline.matching.retrieval", "pipeline.matching.features",
                "pipeline.colmap", "pipeline.colmap.sift", "pipeline.consistency.centralized",
                "pipeline.consistency.spectral", "scipy.optimize", "multiprocessing",
                "concurrent.futures.process", "PIL.PngImagePlugin")


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="*", type=Path, default=None,
                    help="photo folders (default: Sceaux at full size and Graffiti from "
                         f"{SHARED_DATA})")
    ap.add_argument("--quick", action="store_true",
                    help=f"{QUICK_DATA.relative_to(ROOT)} and the ABCD ring only (unless folders or "
                         "--rings are given)")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"comma-separated subset of {','.join(METHODS)}")
    ap.add_argument("--inputs", default="named,renamed", help="named, renamed or both")
    ap.add_argument("--rings", default="ABCD,AABB",
                    help="rendered ring scenes by their sides (comma-separated; empty: none)")
    ap.add_argument("--ring-seeds", default="0",
                    help="render seeds of the ring scenes (comma-separated; default 0)")
    ap.add_argument("--ring-cameras", default=str(RING_CAMERAS),
                    help=f"cameras of each ring, evenly spaced (comma-separated; default "
                         f"{RING_CAMERAS}: 20° apart)")
    ap.add_argument("--rings-only", action="store_true", help="no photo folders")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench-images" / "results.json")
    args = ap.parse_args(argv)
    folders = [] if args.rings_only else \
        (args.folders or ([QUICK_DATA] if args.quick else DEFAULT_DATA))
    from pipeline.commands.options import given_options

    quick_rings = args.quick and "rings" not in given_options(ap, argv)
    rings = ["ABCD"] if quick_rings else [r for r in args.rings.split(",") if r]
    methods = [m for m in args.methods.split(",") if m]
    kinds = [i for i in args.inputs.split(",") if i]
    for flag, given, known in (("--methods", methods, METHODS),
                               ("--inputs", kinds, ("named", "renamed"))):
        if not given or set(given) - set(known):
            bad = ",".join(x for x in given if x not in known) or "''"
            ap.error(f"{flag} {bad}: expected a comma-separated subset of {','.join(known)}")
    for flag, text in (("--ring-seeds", args.ring_seeds), ("--ring-cameras", args.ring_cameras)):
        if not all(x.isdigit() for x in text.split(",") if x):
            ap.error(f"{flag} {text!r}: expected comma-separated whole numbers, e.g. 0,1,2")
    for sides in rings:  # data_synth's ValueError traceback, after the photo folders had run
        if len(sides) != 4 or not sides.isalpha():
            ap.error(f"--rings {sides}: expected four letters, one facade per side of the tower, "
                     "e.g. ABCD or AABB")
    if rings and (few := [x for x in args.ring_cameras.split(",") if x and int(x) < 2]):
        # 0 ended in a traceback, 1 ran every method to fail on one image
        ap.error(f"--ring-cameras {few[0]}: a ring needs at least 2 cameras")
    for folder in folders:
        if not Path(folder).is_dir():
            ap.error(f"{folder}: no such photo folder")
    from pipeline.errors import InputError
    from pipeline.outputs import check_output_files

    try:
        check_output_files([("--out", args.out)], overwrite=True)
    except InputError as exc:
        ap.error(str(exc))
    if not folders and not rings:  # an empty table would replace the previous results
        ap.error("nothing to run: --rings-only with no ring (--rings is empty); name the rings, "
                 "e.g. --rings ABCD, or drop --rings-only")
    import importlib

    for name in WARM_IMPORTS:
        importlib.import_module(name)
    rows = []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-images-") as tmp:
        tmp = Path(tmp)
        ring_seeds = [int(x) for x in args.ring_seeds.split(",") if x]
        ring_cameras = [int(x) for x in args.ring_cameras.split(",") if x]
        cleanings = [m for m in CLEANINGS if m in methods]
        for data, kind, images, truth in _inputs(folders, kinds, tmp, rings, ring_seeds,
                                                 ring_cameras):
            work = tmp / f"{data}-{kind}"
            todo = []
            if {"colmap", *CLEANINGS} & set(methods):
                todo.append(("colmap", None))
            if "colmap-one-camera" in methods:
                todo.append(("colmap-one-camera", "one-camera"))
            todo += [(m, OURS[m]) for m in OURS if m in methods]
            for name, variant in todo:
                print(f"== {data} {kind} {name} ...", file=sys.stderr, flush=True)
                names = ["colmap", *cleanings] if name == "colmap" else [name]
                try:
                    got = (run_colmap(images, work / "colmap", truth, cleanings)
                           if variant is None
                           else run_colmap(images, work / name, truth, (), one_camera=True)
                           if variant == "one-camera"
                           else [run_ours(images, work / name, variant[0], truth,
                                          fusion=variant[1], remap=variant[2])])
                except Exception as exc:  # noqa: BLE001 - a failed run is a result too
                    got = [{"error": f"{type(exc).__name__}: {exc}"}] * len(names)
                for method, row in zip(names, got, strict=True):
                    if method in methods:
                        rows.append({"data": data, "input": kind, "method": method, **row})
                        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
            shutil.rmtree(work, ignore_errors=True)
    header = ("| data | input | method | registered | points | track length | reproj. px "
              "| rot. err. ° (median) | pos. err. m (median) | wrong tracks | time s | CPU s "
              "| features/img |")
    lines = [header, "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['data']} | {r['input']} | {r['method']} | error: {r['error']} "
                         f"| | | | | | | | | |")
            continue
        rot, pos, wrong = _fmt_err(r)
        lines.append(f"| {r['data']} | {r['input']} | {r['method']} | {r['registered']}/"
                     f"{r['images']} | {r['points']} | {r['track_length']:.2f} | "
                     f"{r['reproj_px']:.2f} | {rot} | {pos} | {wrong} | {r['time_s']} | "
                     f"{r.get('cpu_s', '')} | {r['features_mean']} |")
    table = "\n".join(lines)
    print(table)
    targets = _targets(rows)
    for line in targets["lines"]:
        print(line)
    for r in rows:
        if "wrong_links" in r:
            w = r["wrong_links"]
            print(f"{r['data']}: {w['wrong']} of {w['judged']} judged verified matches join "
                  f"different true points; in conflictive sets {w['wrong_in_conflictive_sets']}"
                  f", in two-feature sets {w['wrong_in_two_feature_sets']}, in larger "
                  f"conflict-free sets {w['wrong_in_larger_consistent_sets']}; clean-db cut "
                  f"{w['links'] - w['links_after_clean_db']} links, "
                  f"{w['wrong'] - w['wrong_after_clean_db']} of them wrong")
        if "loop_pairs" in r:
            lp = r["loop_pairs"]
            print(f"{r['data']}: the loop check dropped {lp['wrong_pairs_dropped']} of the "
                  f"{lp['wrong_pairs']} wrong image pairs (most matches joining different true "
                  f"points) and {lp['right_pairs_dropped']} of the "
                  f"{lp['pairs'] - lp['wrong_pairs']} others; "
                  f"{lp['wrong_matches_in_kept_pairs']} of {lp['wrong_matches']} wrong matches "
                  f"are in the pairs it kept")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    import cv2
    import pycolmap

    payload = {"rows": rows, "table": table, "targets": targets, "cores": os.cpu_count(),
               "load_average_at_end": os.getloadavg(),
               "bench_wall_s": round(time.perf_counter() - t_start, 1),
               "python": platform.python_version(), "opencv": cv2.__version__,
               "pycolmap": pycolmap.__version__}
    tmp_out = args.out.with_suffix(".json.tmp")
    tmp_out.write_text(json.dumps(payload, indent=1))
    os.replace(tmp_out, args.out)
    print(f"saved {args.out}")
    return 0


def _targets(rows: list[dict]) -> dict:
    """Ours against colmap per input: points and time ratios; clean-db against colmap alone
    on the inputs with truth: pose errors."""
    by = {(r["data"], r["input"], r["method"]): r for r in rows if "error" not in r}
    out, lines = [], []
    for (data, kind, method), r in sorted(by.items()):
        ref = by.get((data, kind, "colmap"))
        if method == "colmap" or ref is None or not ref["points"]:
            continue
        item = {"data": data, "input": kind, "method": method,
                "points_ratio": round(r["points"] / ref["points"], 3),
                "time_ratio": round(r["time_s"] / ref["time_s"], 3) if ref["time_s"] else None,
                "cpu_ratio": round(r["cpu_s"] / ref["cpu_s"], 3)
                if ref.get("cpu_s") and "cpu_s" in r else None}
        for key, what in (("seeds", ""), ("seeds_min15", " at 15 pose inliers")):
            if not (ref.get(key) and r.get(key)):
                continue
            got = {f: [[x[f]["median"] if x.get(f) else None for x in row[key]]
                       for row in (ref, r)] for f in ("rotation_deg", "position_m")}
            got["registered"] = [[x.get("registered") for x in row[key]] for row in (ref, r)]
            got["wrong_tracks"] = [[x.get("wrong_tracks") for x in row[key]] for row in (ref, r)]
            item[f"{key}_rotation_median_deg"] = got["rotation_deg"]
            item[f"{key}_wrong_tracks"] = got["wrong_tracks"]
            item[f"{key}_position_median_m"] = got["position_m"]
            item[f"{key}_registered"] = got["registered"]
            lines.append(f"{data} {kind} {method} vs colmap, mapping seeds {list(SEEDS)}{what}: "
                         f"registered {got['registered'][1]} vs {got['registered'][0]}, "
                         f"rotation median {got['rotation_deg'][1]} ° vs "
                         f"{got['rotation_deg'][0]} °, position median {got['position_m'][1]} m "
                         f"vs {got['position_m'][0]} m, wrong tracks {got['wrong_tracks'][1]} "
                         f"vs {got['wrong_tracks'][0]}")
        if r.get("rotation_deg") and ref.get("rotation_deg"):
            item["rotation_median_deg"] = [ref["rotation_deg"]["median"],
                                           r["rotation_deg"]["median"]]
            item["position_median_m"] = [ref["position_m"]["median"], r["position_m"]["median"]]
            item["wrong_tracks"] = [ref["wrong_tracks"], r["wrong_tracks"]]
        out.append(item)
        lines.append(f"{data} {kind} {method}: points {item['points_ratio']:.3f} x colmap's, "
                     f"time {item['time_ratio']} x colmap's (CPU {item['cpu_ratio']} x)"
                     + (f"; rotation median {item['rotation_median_deg'][1]} ° vs colmap "
                        f"{item['rotation_median_deg'][0]} °, position median "
                        f"{item['position_median_m'][1]} m vs {item['position_median_m'][0]} m, "
                        f"wrong tracks {item['wrong_tracks'][1]} vs {item['wrong_tracks'][0]}"
                        if "rotation_median_deg" in item else ""))
    return {"items": out, "lines": lines}


if __name__ == "__main__":
    sys.exit(main())
