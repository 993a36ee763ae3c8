"""Benchmark: teams started one after another, each from a zygote of its own or all from one.

A command that starts several teams of robot processes (``run-formations``, an online run:
three per step) forks all their robots from one zygote that imported the robot program
once (:func:`pipeline.team.launcher.shared_zygote`); ``FORMATION_MATCH_ZYGOTE=team`` gives
each team its own, which imports the program again. Side by side in one run, alternated
``--repeat`` times: ``--teams`` consecutive ``resolve`` teams of ``--robots`` robot processes
(a ring of cameras, each linked to the next by a few links, one conflictive set across the
ring), per-team wall time from the launch to the last robot's exit, median over the repeats,
and whether every team cut the same links. Saves ``runs/bench-team-starts/results.json``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

from pipeline.commands.options import count_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

#: most robots per team here: every robot is a process on this machine
MAX_ROBOTS = 16


def robots_argument(text: str) -> int:
    """``--robots``: a whole number of robot processes from 3 to :data:`MAX_ROBOTS`."""
    try:
        n = int(text)
    except ValueError:
        n = None
    if n is None or not 3 <= n <= MAX_ROBOTS:
        raise argparse.ArgumentTypeError(f"{text!r}: give a whole number of robots from 3 to "
                                         f"{MAX_ROBOTS} (each is a process on this machine)")
    return n


def ring_links(folder: Path, n: int) -> tuple[Path, list[int], list[list[int]]]:
    """A links file of ``n`` cameras in a ring, two features each: feature 0 of each camera
    linked to feature 0 of the next, and one link closing the ring on feature 1 (a
    conflictive set: camera 0's two features joined). Returns its path, the features per
    camera and the comm edges (the ring)."""
    rows = ["cam_i,feat_i,cam_j,feat_j"]
    rows += [f"{i},0,{i + 1},0" for i in range(n - 1)] + [f"0,1,{n - 1},0"]
    path = folder / "ring.csv"
    path.write_text("\n".join(rows) + "\n")
    return path, [2] * n, [[i, (i + 1) % n] for i in range(n)]


def run_teams(links: Path, fpc, edges, teams: int, shared: bool) -> tuple[float, list]:
    """``teams`` consecutive ``resolve`` teams; (seconds per team, each team's cut mask)."""
    import contextlib

    from pipeline.runs.transports.zenoh import resolve_links_file
    from pipeline.team.launcher import shared_zygote

    cuts = []
    t0 = time.perf_counter()
    with shared_zygote() if shared else contextlib.nullcontext():
        for _ in range(teams):
            cuts.append(resolve_links_file(links, fpc, edges).deleted.tolist())
    return (time.perf_counter() - t0) / teams, cuts


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--robots", type=robots_argument, default=4,
                    help=f"robot processes per team (3 to {MAX_ROBOTS}; default 4)")
    ap.add_argument("--teams", type=count_argument, default=6,
                    help="consecutive teams per measurement (default 6)")
    ap.add_argument("--repeat", type=count_argument, default=3,
                    help="measurements of each side, alternated; the median kept (default 3)")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-team-starts"))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    load = [round(x, 2) for x in os.getloadavg()]
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")
    sides = {"a zygote per team": False, "one zygote for all": True}
    per_team: dict[str, list[float]] = {k: [] for k in sides}
    cuts: dict[str, list] = {k: [] for k in sides}
    with tempfile.TemporaryDirectory() as tmp:
        links, fpc, edges = ring_links(Path(tmp), args.robots)
        for r in range(args.repeat):
            for name, shared in sides.items():
                s, c = run_teams(links, fpc, edges, args.teams, shared)
                per_team[name].append(round(s, 3))
                cuts[name] += c
                print(f"  repeat {r}: {name}: {s:.3f} s per team", flush=True)
    first = next(iter(cuts.values()))[0]
    same = all(c == first for cs in cuts.values() for c in cs)
    med = {k: statistics.median(v) for k, v in per_team.items()}
    ratio = med["one zygote for all"] / med["a zygote per team"]
    print(f"{args.teams} consecutive teams of {args.robots} robot processes, {args.repeat} "
          f"measurement(s) each; seconds per team (median): "
          + ", ".join(f"{k} {v:.3f}" for k, v in med.items())
          + f"; one zygote / a zygote per team: {ratio:.2f}; the same cuts in every team: {same}")
    load_end = [round(x, 2) for x in os.getloadavg()]
    print(f"load average at the end: {load_end}")
    write_json_atomic(Path(args.out) / "results.json", {
        "robots": args.robots, "teams": args.teams, "repeat": args.repeat,
        "cpus": os.cpu_count(), "load_average_at_start": load, "load_average_at_end": load_end,
        "seconds_per_team": per_team, "median_seconds_per_team": med,
        "ratio_one_zygote_to_per_team": round(ratio, 3), "same_cuts": same})
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
