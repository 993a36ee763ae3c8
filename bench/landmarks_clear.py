"""Benchmark: our side of the CLEAR comparison on the CMU hotel landmarks.

CLEAR (Fathian et al., T-RO 2020; public code mit-acl/clear) is a centralized spectral
multi-view matcher. Measured on this machine with its public code, on pairwise Hungarian
matching of the shape contexts (χ²) of all 101 frames, complete graph: input pairwise F1
0.907 → CLEAR 0.983, cycle-consistent, 41 s; on 20 frames 0.910 → 0.981 in 0.8 s. Those are
CLEAR's figures, not ours; this script runs what we can run ourselves on the same inputs.

For 20 frames (stride 5: frames 0, 5, …, 95 — the subset whose input F1 is CLEAR's 0.910)
and all 101 frames, on the complete graph, a ring and ``seq:4`` (each frame with its 4
nearest in sequence order): ``run-landmarks`` on the ungated Hungarian matches (CLEAR's
input) with each resolution method, in the configurations ``--configs``
``REFINE:RATIO:GEOMETRY`` (default ``votes:none:epipolar`` = the default run: guided
matching, refined by votes; ``votes:none:none`` = descriptor-only matches refined by votes;
``none:none:none`` = CLEAR's input straight into the resolution; a ratio such as 0.8 adds
the gate), plus the centralized baselines on the same links. Times: wall and CPU of the one process that
simulates every robot in turn (``refine`` + ``resolution``, the stages CLEAR's time
compares to; matching is the shared input). Scores are CLEAR's: pairwise P/R/F1 of the matches
implied by the closure of the kept links, against the labels.

Prints a table; saves ``runs/bench-landmarks/results.json`` (one record per run).

Usage: ``.venv/bin/python bench/landmarks_clear.py [--data DIR] [--frames 20 101] [--configs ...]
[--graphs complete ring seq:4] [--quick]`` (``--quick``: 20 frames, unless ``--frames`` is given).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

from multiway import SHARED_DATA  # noqa: E402

from pipeline.commands.options import given_options  # noqa: E402
from pipeline.consistency.rules import RULES as RESOLUTIONS  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.progress import StageTimer  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402
from pipeline.runs.landmarks import LandmarksConfig, run_landmarks  # noqa: E402

CLEAR_MEASURED = {  # measured on this machine with CLEAR's public code (not our figures)
    (101, "complete"): {"input_f1": 0.907, "f1": 0.983, "time_s": 41.0},
    (20, "complete"): {"input_f1": 0.910, "f1": 0.981, "time_s": 0.8},
}


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=SHARED_DATA / "cmu_hotel")
    ap.add_argument("--frames", type=int, nargs="+", default=[20, 101])
    ap.add_argument("--graphs", nargs="+", default=["complete", "ring", "seq:4"])
    ap.add_argument("--configs", nargs="+",
                    default=["votes:none:epipolar", "votes:none:none", "none:none:none"],
                    help="REFINE:RATIO:GEOMETRY[:PX] (refine votes|none, ratio none|R, geometry "
                         "epipolar|none, epipolar bound PX, default 3)")
    ap.add_argument("--results", default="results.json", help="file name under --out")
    ap.add_argument("--quick", action="store_true", help="20 frames only, unless --frames is given")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench-landmarks")
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    if args.results in ("", ".", "..") or Path(args.results).name != args.results:
        # a folder, '' or a path through one was refused only when saving, after every run
        ap.error(f"--results {args.results!r}: give a file name, saved under --out (e.g. "
                 "results-20.json)")
    if (args.out / args.results).is_dir():
        ap.error(f"--results {args.results!r}: {str(args.out / args.results)!r} is a folder; "
                 "give another file name")
    for conf in args.configs:
        if _config(conf) is None:
            ap.error(f"--configs {conf!r}: expected REFINE:RATIO:GEOMETRY[:PX], e.g. "
                     "votes:none:epipolar or none:0.8:epipolar:2")
    if not args.data.is_dir():
        print(f"error: --data {args.data}: no such folder; give the CMU hotel folder (its frames "
              "and their label files)", file=sys.stderr)
        return 2
    frames = [20] if args.quick and "frames" not in given_options(ap, argv) else args.frames
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    records = []
    for n in frames:
        for graph in args.graphs:
            for conf in args.configs:
                refine, ratio_text, ratio, geometry, px = _config(conf)
                for method in RESOLUTIONS:
                    name = (f"f{n}-{graph.replace(':', '')}-{geometry}{''.join(px)}-{refine}"
                            f"-r{ratio_text}"
                            f"-{method}")
                    cfg = LandmarksConfig(directory=str(args.data), graph=graph, frames=n,
                                          ratio=ratio, geometry=geometry, refine=refine,
                                          epipolar_px=float(px[0]) if px else 3.0,
                                          resolution=method, out=str(args.out / name))
                    t0 = time.perf_counter()
                    _, rep = run_landmarks(cfg, StageTimer(verbose=False))
                    wall = time.perf_counter() - t0
                    r, pw = rep["resolution"], rep["pairwise"]
                    rec = {
                        "frames": n, "graph": graph, "ratio": ratio,
                        "geometry": geometry + (f" {px[0]} px" if px else ""),
                        "refine": refine, "matching": rep["matching"],
                        "method": method, "refinement": rep["refinement"],
                        "comm_edges": len(rep["comm_edges"]), "links": rep["before"]["links"],
                        "input_links": pw["input_links"], "before": pw["before"],
                        "after": pw["after"], "cycle_consistent": rep["cycle_consistent"],
                        "rounds": (r["detection_rounds"] or 0) + (r["resolution_rounds"] or 0)
                        + rep["refinement"].get("rounds", 0),
                        "messages": r["messages"] + rep["refinement"].get("messages", 0),
                        "bytes": r["bytes"] + rep["refinement"].get("bytes", 0),
                        "stage_wall_s": round(r["time_s"] + rep["timings_s"].get("refine", 0), 3),
                        "stage_cpu_s": round(r["cpu_s"] + rep["refinement"].get("cpu_s", 0), 3),
                        "matching_time_s": rep["timings_s"].get("matching"),
                        "wall_s": round(wall, 3),
                        "baselines": {k: {"f1": v["pairwise"]["f1"],
                                          "precision": v["pairwise"]["precision"],
                                          "recall": v["pairwise"]["recall"],
                                          "time_s": v["time_s"]}
                                      for k, v in rep["baselines"].items()},
                        "clear_measured_here": CLEAR_MEASURED.get((n, graph)),
                    }
                    records.append(rec)
                    print(_row(rec), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    meta = {"python": platform.python_version(), "machine": platform.machine(),
            "cpus": __import__("os").cpu_count(), "data": str(args.data)}
    write_json_atomic(args.out / args.results, {"meta": meta, "records": records})
    print(f"saved {args.out / args.results}")
    return 0


HEADER = ("| frames | graph | geometry | refine | gate | resolution | Hungarian F1 | P / R / F1 after "
          "| cycle-consistent | rounds | messages | MB | wall s | CPU s | quality_merge F1 | "
          "keep_first F1 | drop_sets F1 |")


def _config(conf: str):
    """``REFINE:RATIO:GEOMETRY[:PX]`` as ``(refine, ratio text, ratio, geometry, [px])``;
    None if it does not read so."""
    parts = conf.split(":")
    if len(parts) not in (3, 4):
        return None
    refine, ratio_text, geometry, *px = parts
    try:
        ratio = None if ratio_text == "none" else float(ratio_text)
        if px:
            float(px[0])
    except ValueError:
        return None
    return refine, ratio_text, ratio, geometry, px


def _row(r: dict) -> str:
    a, b = r["after"], r["baselines"]
    gate = "none" if r["ratio"] is None else f"ratio {r['ratio']}"
    return (f"| {r['frames']} | {r['graph']} | {r['geometry']} | {r['refine']} | {gate} | {r['method']} | "
            f"{r['input_links']['f1']:.3f} | "
            f"{a['precision']:.3f} / {a['recall']:.3f} / {a['f1']:.3f} | {r['cycle_consistent']} | "
            f"{r['rounds']} | {r['messages']} | {r['bytes'] / 1e6:.1f} | "
            f"{r['stage_wall_s']:.2f} | {r['stage_cpu_s']:.2f} | {b['quality_merge']['f1']:.3f} | "
            f"{b['keep_first_per_image']['f1']:.3f} | {b['drop_conflictive_sets']['f1']:.3f} |")


if __name__ == "__main__":
    sys.exit(main())
