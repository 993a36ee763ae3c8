"""Benchmark: render, feature extraction and neighbour-only matching of one formation.

For each feature method (SIFT, ORB, AKAZE) renders the formation (default d: 6 cameras,
640x480), extracts features and matches every communication edge, ``--repeat`` times, and
prints the median (and minimum) wall time of each stage next to the 3 s target for
render + extract + match with SIFT.

It also times extraction serially (default: a 2-thread pool) and matching serially (float
descriptors: one product at a time on every BLAS thread) and with 2 threads (float
descriptors: one BLAS thread per product; the default for both kinds, except float
distance matrices over 64 MiB); the defaults of
:func:`pipeline.matching.features.extract_all` and :func:`pipeline.matching.pairs.match_edges` follow these
figures. Saves ``runs/bench-foundation/results.json``. Run 0 of each method is a warm-up and
not counted.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import cv2  # noqa: E402
import numpy as np  # noqa: E402

import data_synth  # noqa: E402
from pipeline.association import AssociationGraph, count_conflicts  # noqa: E402
from pipeline.commands.options import count_argument, seed_argument  # noqa: E402
from pipeline.errors import InputError, one_line_errors  # noqa: E402
from pipeline.matching.features import extract_all  # noqa: E402
from pipeline.matching.pairs import match_edges  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402
from pipeline.types import Links  # noqa: E402

TARGET_S = 3.0


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def bench_method(method: str, args, size) -> dict:
    runs = []
    for k in range(args.repeat + 1):
        f, t_render = _timed(lambda: data_synth.render(args.formation, seed=args.seed, size=size))
        feats, t_extract = _timed(lambda f=f: extract_all(f.views, method, args.max_features))
        matches, t_match = _timed(lambda f=f, feats=feats: match_edges(feats, f.views, f.comm_edges))
        _, t_extract_1 = _timed(lambda f=f: extract_all(f.views, method, args.max_features, workers=1))
        _, t_match_1 = _timed(lambda f=f, feats=feats: match_edges(feats, f.views, f.comm_edges,
                                                                   workers=1))
        _, t_match_2 = _timed(lambda f=f, feats=feats: match_edges(feats, f.views, f.comm_edges,
                                                                   workers=2))
        if k == 0:
            continue  # warm-up: imports, OpenCV and BLAS thread pools
        links = Links.from_matches(matches)
        counts = count_conflicts(AssociationGraph([len(x) for x in feats], links))
        runs.append({"render_s": t_render, "extract_s": t_extract, "match_s": t_match,
                     "total_s": t_render + t_extract + t_match,
                     "extract_serial_s": t_extract_1, "match_serial_s": t_match_1,
                     "match_2threads_s": t_match_2,
                     "features": int(sum(len(x) for x in feats)), "links": len(links),
                     "conflictive_sets": counts.conflictive_sets,
                     "edges": len(matches)})
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    best = {k: min(r[k] for r in runs) for k in runs[0] if k.endswith("_s")}
    return {"method": method, "runs": runs, "median": med, "min": best}


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--formation", default="d")
    ap.add_argument("--seed", type=seed_argument, default=0)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--max-features", type=int, default=2000)
    ap.add_argument("--methods", default="sift,orb,akaze")
    ap.add_argument("--repeat", type=count_argument, default=3)
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-foundation"))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        ap.error(f"--size {args.size!r}: expected WIDTHxHEIGHT in pixels, e.g. 640x480")

    from pipeline.matching.features import METHODS

    methods = args.methods.split(",")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:  # before any method runs (a bad one last ran the others first)
        print(f"error: unknown feature method {unknown[0]!r} (--methods); choose from "
              f"{', '.join(METHODS)}", file=sys.stderr)
        return 2
    load_before = os.getloadavg()
    try:
        results = [bench_method(m, args, (w, h)) for m in methods]
    except InputError as exc:  # a formation, size or feature method the pipeline refuses
        print(f"error: {exc}", file=sys.stderr)
        return 2
    load_after = os.getloadavg()
    print(f"\nformation {args.formation}, seed {args.seed}, {w}x{h}, at most {args.max_features} "
          f"features, median of {args.repeat} runs (min in brackets), {os.cpu_count()} cores, "
          f"cv2 threads {cv2.getNumThreads()}, load average {load_before[0]:.1f} -> "
          f"{load_after[0]:.1f} (other processes inflate wall times; min is the least disturbed)")
    cols = ["render_s", "extract_s", "match_s", "total_s", "extract_serial_s", "match_serial_s",
            "match_2threads_s",
            "features", "links", "conflictive_sets"]
    print(f"{'method':<8}" + "".join(f"{c:>18}" for c in cols))
    for r in results:
        med, best = r["median"], r["min"]
        print(f"{r['method']:<8}" + "".join(
            f"{f'{med[c]:.3f} ({best[c]:.3f})':>18}" if c.endswith("_s") else f"{int(med[c]):>18d}"
            for c in cols))
    sift = next((r for r in results if r["method"] == "sift"), None)
    verdict = None
    if sift is not None:
        verdict = bool(sift["median"]["total_s"] < TARGET_S)
        print(f"target: SIFT render + extract + match < {TARGET_S} s → "
              f"{'met' if verdict else 'NOT met'} ({sift['median']['total_s']:.2f} s)")
    write_json_atomic(Path(args.out) / "results.json", {
        "config": vars(args), "cores": os.cpu_count(), "cv2_threads": cv2.getNumThreads(),
        "numpy": np.__version__, "opencv": cv2.__version__, "target_s": TARGET_S,
        "load_average_before": load_before, "load_average_after": load_after,
        "target_met": verdict, "results": results})
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
