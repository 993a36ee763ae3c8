"""Benchmark: one cycle through ``n`` cameras through ``python -m pipeline resolve``.

The input is a links file of ``n`` lines: camera ``i`` linked to ``i + 1`` by feature 0, the
last camera back to camera 0 by its feature 1 — one conflictive set as long as the team, the
worst case of the detection's ``d + 1`` rounds (Cor. 3.6) and of Alg. 1's ``n`` rounds
(Thm. 4.3). Each run is a whole process (start-up included); its wall time and peak resident
memory (``ru_maxrss`` of that child alone, by ``os.wait4``) are measured, with both
resolutions (Alg. 1: ``--resolution paper``; the default ``evidence`` rule, whose robots merge
a set beyond their bundle budget, as this one is, by the ``sync`` merge, every link tied:
in the pseudo-random order of ``pipeline.consistency.keys.tie_key``, evaluated in batch by
the simulator), the two side by side for each ``n``, ``--repeat`` times in turn (medians).
Target (1000 cameras): under 5 s and 500 MB.

Prints a table and saves ``runs/bench-consistency-cycle/results.json``.

Usage: ``.venv/bin/python bench/consistency_cycle.py [--n 100 1000] [--repeat 3]
[--evidence-max-n N]``
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402

from pipeline.commands.options import count_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

OUT = ROOT / "runs" / "bench-consistency-cycle"
TARGET_N, TARGET_S, TARGET_MB = 1000, 5.0, 500.0


def write_cycle(path: Path, n: int) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        for i in range(n - 1):
            w.writerow([i, 0, i + 1, 0])
        w.writerow([0, 1, n - 1, 0])


def run_resolve(links: Path, out: Path, resolution: str) -> dict:
    """One ``resolve`` process: wall time, peak RSS (MB), exit code, links cut."""
    cmd = [sys.executable, "-m", "pipeline", "resolve", "--links", str(links), "--out",
           str(out), "--resolution", resolution, "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace").strip() if proc.stderr else ""
    cut = 0
    if proc.returncode == 0:
        with open(out, newline="") as f:
            cut = sum(1 for r in csv.DictReader(f) if r["status"] == "deleted")
    return dict(wall_s=round(wall, 3), peak_rss_mb=round(usage.ru_maxrss / 1024, 1),
                exit_code=proc.returncode, deleted=cut, stderr=err[-300:])


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100, 1000])
    ap.add_argument("--evidence-max-n", type=int, default=None,
                    help="run the evidence rule only up to this n (default: every n)")
    ap.add_argument("--repeat", type=count_argument, default=3,
                    help="runs of each process, the resolutions in turn (medians reported)")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    if min(args.n) < 2:
        ap.error(f"--n {min(args.n)}: a cycle joins at least 2 cameras")

    load_start = os.getloadavg()
    records = []
    print(f"{'n':>6} {'resolution':>10} {'wall s':>8} {'peak MB':>8} {'exit':>4} {'cut':>4} "
          f"{'wall s of each run':>20}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.n:
            links = Path(tmp) / f"cycle{n}.csv"
            write_cycle(links, n)
            resolutions = [r for r in ("paper", "evidence")
                           if r == "paper" or args.evidence_max_n is None
                           or n <= args.evidence_max_n]
            runs: dict[str, list[dict]] = {r: [] for r in resolutions}
            for k in range(max(1, args.repeat)):
                for resolution in resolutions:
                    runs[resolution].append(run_resolve(
                        links, Path(tmp) / f"out{n}-{resolution}-{k}.csv", resolution))
            for resolution in resolutions:
                rs = runs[resolution]
                r = dict(rs[len(rs) // 2])
                r.update(wall_s=round(float(np.median([x["wall_s"] for x in rs])), 3),
                         peak_rss_mb=round(float(np.median([x["peak_rss_mb"] for x in rs])), 1),
                         exit_code=max(x["exit_code"] for x in rs),
                         runs_wall_s=[x["wall_s"] for x in rs],
                         runs_peak_rss_mb=[x["peak_rss_mb"] for x in rs],
                         n=n, resolution=resolution)
                records.append(r)
                each = " ".join(f"{x:.2f}" for x in r["runs_wall_s"])
                print(f"{n:>6} {resolution:>10} {r['wall_s']:>8.2f} {r['peak_rss_mb']:>8.1f} "
                      f"{r['exit_code']:>4} {r['deleted']:>4} {each:>20}", flush=True)
                if r["exit_code"] != 0:
                    print(f"       stderr: {r['stderr']}")
    for r in records:
        if r["n"] == TARGET_N:
            ok = r["wall_s"] < TARGET_S and r["peak_rss_mb"] < TARGET_MB
            print(f"target: {TARGET_N}-camera cycle, {r['resolution']}: {r['wall_s']:.2f} s, "
                  f"{r['peak_rss_mb']:.0f} MB ({'within' if ok else 'OVER'} {TARGET_S:.0f} s "
                  f"and {TARGET_MB:.0f} MB)")
    load_end = os.getloadavg()
    print(f"load average {load_start[0]:.1f} at the start, {load_end[0]:.1f} at the end "
          f"({os.cpu_count()} cores)")
    args.out.mkdir(parents=True, exist_ok=True)
    # one file: the figures and what they were measured on are replaced together
    write_json_atomic(args.out / "results.json",
                      dict(meta=dict(python=platform.python_version(), machine=platform.machine(),
                                     repeat=args.repeat, load_average_at_start=load_start,
                                     load_average=load_end, command=" ".join(sys.argv)),
                           records=records))
    print(f"saved {args.out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
