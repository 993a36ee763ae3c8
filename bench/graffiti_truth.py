"""Benchmark: run-images on Graffiti against its exact ground truth, on three graphs.

    python bench/graffiti_truth.py [DIR] [--graphs ring ring2 complete] [--out runs/bench-graffiti]

``python -m pipeline run-images DIR --graph G --truth homographies --no-rerun`` at the photo
defaults (the evidence rule, then fusion; ground truth from the data set's homographies at
2 px, mutual) for each graph ``G``, each a whole command-line run. Prints the README's table
(features, links, good / spurious / missing links, conflictive sets, what resolution and
fusion cut and how much of it was good, pairwise P/R/F1 after each stage, the centralized
baselines) and the load average at the start and the end, and saves
``OUT/results.json`` with every run's report. DIR defaults to ``../shared/data/graffiti``
beside the repository (the 800x640 Oxford Graffiti sequence with ``H1to{k}p.txt``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402
from multiway import SHARED_DATA  # noqa: E402

from pipeline.commgraph import comm_graph  # noqa: E402
from pipeline.errors import InputError, one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402


def run_graph(directory: Path, graph: str, out: Path) -> dict:
    """The report of one run-images run on ``graph`` (its run folder under ``out``, named by
    the graph kind, or a graph file's name without suffix, as run-images names it)."""
    folder = out / (Path(graph).stem if Path(graph).is_file() else graph.replace(":", ""))
    done = subprocess.run([sys.executable, "-m", "pipeline", "run-images", str(directory),
                           "--graph", graph, "--truth", "homographies", "--no-rerun", "--out",
                           str(folder), "--quiet"], cwd=ROOT, capture_output=True, text=True)
    if done.returncode == 2:  # the user's input refused (a bad graph file): its one line
        errors = [line for line in done.stderr.splitlines() if line.startswith("error: ")]
        raise InputError(errors[-1].removeprefix("error: ") if errors else done.stderr.strip())
    if done.returncode != 0:
        raise SystemExit(f"run-images --graph {graph} exited {done.returncode}:\n{done.stderr}")
    return json.loads((folder / "report.json").read_text())


def _f(x: float) -> str:
    return f"{x:.3f}"


def _prf(p: dict) -> str:
    return f"{_f(p['precision'])} / {_f(p['recall'])} / {_f(p['f1'])}"


def table(reports: dict[str, dict], edges: dict[str, int]) -> str:
    """The markdown table of the README, one column per graph."""
    rows = {
        "Features per image (mean)": lambda r: f"{sum(r['features_per_camera']) / len(r['features_per_camera']):.0f}",
        "Links before → after": lambda r: f"{r['before']['links']} → {r['after']['links']}",
        "Good / spurious links before": lambda r: f"{r['before']['good_links']} / {r['before']['spurious_links']}",
        "Good / spurious links after": lambda r: f"{r['after']['good_links']} / {r['after']['spurious_links']}",
        "Missing links before → after": lambda r: f"{r['before']['missing_links']} → {r['after']['missing_links']}",
        "Conflictive sets before → after": lambda r: f"{r['before']['conflictive_sets']} → {r['after']['conflictive_sets']}",
        "Cut by resolution (good / spurious)": lambda r: (
            f"{r['resolution']['deleted_links']} ({r['resolution']['good_deleted']} / "
            f"{r['resolution']['spurious_deleted']})"),
        "Cut by fusion (good / spurious)": lambda r: (
            f"{r['fusion']['links_cut']} ({r['fusion']['cut_good']} / {r['fusion']['cut_spurious']})"),
        "Pairwise P / R / F1 before": lambda r: _prf(r["pairwise"]["before"]),
        "Pairwise P / R / F1 after resolution": lambda r: _prf(r["pairwise"]["after_resolution"]),
        "Pairwise P / R / F1 after fusion": lambda r: _prf(r["pairwise"]["after"]),
        "Baseline drop conflictive sets: spurious kept, F1": lambda r: _baseline(r, "drop_conflictive_sets"),
        "Baseline keep first per image: spurious kept, F1": lambda r: _baseline(r, "keep_first_per_image"),
        "Baseline quality merge: spurious kept, F1": lambda r: _baseline(r, "quality_merge"),
    }
    head = ("| Graffiti, `--truth homographies` (2 px), defaults (`--resolution evidence`) | "
            + " | ".join(f"{g} ({edges[g]} edges)" for g in reports) + " |")
    lines = [head, "|---|" + "---:|" * len(reports)]
    lines += [f"| {name} | " + " | ".join(fmt(r) for r in reports.values()) + " |"
              for name, fmt in rows.items()]
    return "\n".join(lines)


def _baseline(report: dict, name: str) -> str:
    b = report["baselines"][name]
    return f"{b['spurious_links']}, {_f(b['pairwise']['f1'])}"


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("directory", nargs="?", type=Path,
                    default=SHARED_DATA / "graffiti")
    ap.add_argument("--graphs", nargs="+", default=["ring", "ring2", "complete"])
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench-graffiti")
    args = ap.parse_args(argv)
    # run-images runs in the repository: relative paths are the caller's
    args.directory, args.out = args.directory.absolute(), args.out.absolute()
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    if not (args.directory / "H1to2p.txt").is_file():
        print(f"error: {args.directory}: no Graffiti homographies (H1to2p.txt); give the folder",
              file=sys.stderr)
        return 2
    for graph in args.graphs:  # an unknown kind, before any run (run-images checks a file)
        if not Path(graph).is_file():
            comm_graph(graph, ["img1", "img2"], knn=lambda k: np.zeros((0, 2), dtype=int))
    # a graph file as the caller names it (run-images runs in the repository)
    args.graphs = [str(Path(g).absolute()) if Path(g).is_file() else g for g in args.graphs]
    load = [round(x, 2) for x in os.getloadavg()]
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")
    reports = {g: run_graph(args.directory, g, args.out) for g in args.graphs}
    load_end = [round(x, 2) for x in os.getloadavg()]
    edges = {g: len(r["comm_edges"]) for g, r in reports.items()}
    print(table(reports, edges))
    print(f"load average at the end: {load_end}")
    # written beside and renamed into place: an interrupted or failed write leaves the
    # previous results.json as it was
    write_json_atomic(args.out / "results.json",
                      {"directory": str(args.directory), "load_average_at_start": load,
                       "load_average_at_end": load_end, "reports": reports})
    print(f"saved {args.out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
