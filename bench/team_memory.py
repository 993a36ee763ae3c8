"""Benchmark: the private memory of robot processes over Zenoh, with and without Zenoh's shared memory.

A robot process's memory is mostly its interpreter and libraries, shared with the other robots
through the zygote that forks them (:mod:`pipeline.team.zygote`): what each robot adds is its
*private* memory (``Private_Dirty`` of ``/proc/PID/smaps_rollup``: pages this process alone
wrote). Zenoh 1.x turns on its shared-memory transport between the sessions of one host by
default; the team option ``shared_memory`` (:data:`pipeline.team.teamfile.DEFAULT_OPTIONS`,
off by default) decides it for the robots (:func:`pipeline.transport.zenoh_transport.zenoh_config`).

For each team size ``N`` (``--robots``; a rendered formation of ``N`` robots on the complete
graph, each robot ``N - 1`` neighbours), the same ``run-formation --transport zenoh`` run
(``--size``, ``--max-features``, no fusion, no recording) with the option off and on, side by
side in one run (``--repeat`` times, alternating): the peak private memory of every robot
process (sampled every 0.02 s while the team runs: robots forked by a warm zygote may live
under 0.2 s; min / median / max over the robots), the
wall time of the team and the CPU time of the whole run (this process and its children),
and whether the two runs kept the same links (``links.csv``: statuses and reasons). Prints a
table and saves ``runs/bench-team-memory/results.json``.

Usage: ``.venv/bin/python bench/team_memory.py [--robots 12 30] [--repeat 1]``
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

from pipeline.commands.options import count_argument, parse_size, size_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402


def _children(pid: int) -> list[int]:
    out: list[int] = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                out += [int(x) for x in f.read().split()]
    except OSError:  # gone meanwhile
        pass
    return out


def private_mb(pid: int) -> float | None:
    """``Private_Dirty`` of ``pid`` in MB (None: gone, or no smaps_rollup)."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Private_Dirty:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


class RobotSampler:
    """Samples, every ``period_s`` (or the time a sweep took, if longer), the private memory of the grandchildren of this process
    (the robots the zygote forked; the zygote itself is a child) and keeps each one's peak."""

    def __init__(self, period_s: float = 0.02) -> None:
        self.period_s = period_s
        self.peak: dict[int, float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        me = os.getpid()
        while not self._stop.is_set():
            t0 = time.perf_counter()
            for zygote in _children(me):
                for robot in _children(zygote):
                    v = private_mb(robot)
                    if v is not None:
                        self.peak[robot] = max(self.peak.get(robot, 0.0), v)
            # a sweep reads ~0.7 ms per robot: at least as long again idle, so that sampling
            # a large team takes at most half a core from it
            self._stop.wait(max(self.period_s, time.perf_counter() - t0))

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def one_run(n: int, shared_memory: bool, a, out: Path) -> dict:
    """One ``run-formation --transport zenoh`` of ``n`` robots on the complete graph."""
    import json

    from pipeline.runs.formation import FormationConfig, run_formation

    cfg = FormationConfig(formation="d", seed=a.seed, size=parse_size(a.size),
                          max_features=a.max_features,
                          robots=n, graph="complete", fusion=False, rerun=False, out=str(out))
    runs: list = []
    cpu0 = os.times()
    t0 = time.perf_counter()
    with RobotSampler() as sampler, contextlib.redirect_stdout(io.StringIO()):  # its tables
        run_formation(cfg, transport="zenoh", keep_run=runs, shared_memory=shared_memory)
    wall = time.perf_counter() - t0
    cpu1 = os.times()
    cpu = sum(getattr(cpu1, k) - getattr(cpu0, k)
              for k in ("user", "system", "children_user", "children_system"))
    peaks = sorted(sampler.peak.values())
    rows = [tuple(line.split(",")[:6]) for line in (out / "links.csv").read_text().splitlines()]
    report = json.loads((out / "report.json").read_text())
    return {"robots": n, "shared_memory": shared_memory, "robot_processes_sampled": len(peaks),
            "private_mb_min": round(peaks[0], 1) if peaks else None,
            "private_mb_median": round(peaks[len(peaks) // 2], 1) if peaks else None,
            "private_mb_max": round(peaks[-1], 1) if peaks else None,
            "private_mb_sum": round(sum(peaks), 1),
            "team_wall_s": round(float(runs[0].wall_s), 2) if runs else None,
            "run_wall_s": round(wall, 2), "run_cpu_s": round(cpu, 2),
            "links_deleted": int(report["before"]["links"] - report["after"]["links"]),
            "_rows": rows}


@one_line_errors
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=count_argument, nargs="+", default=[12, 30])
    p.add_argument("--repeat", type=count_argument, default=1)
    p.add_argument("--size", type=size_argument, default="160x120")
    p.add_argument("--max-features", type=count_argument, default=200)
    p.add_argument("--seed", type=count_argument, default=1)
    p.add_argument("--out", default=str(ROOT / "runs" / "bench-team-memory"))
    a = p.parse_args(argv)
    if problem := results_folder_problem(a.out):
        p.error(problem)
    if bad := [n for n in a.robots if not 2 <= n <= 256]:
        p.error(f"--robots {bad[0]}: a team of 2 to 256 robot processes")
    load0 = os.getloadavg()
    records = []
    print("robot processes over zenoh, complete graph: private memory per robot (min / median "
          "/ max MB), team wall, run CPU; shared_memory off against on")
    with tempfile.TemporaryDirectory(prefix="bench-team-memory-") as tmp:
        for n in a.robots:
            # a first run renders the formation into the cache (each robot renders its own
            # camera, with the memory that takes); the measured runs all find it there
            one_run(n, False, a, Path(tmp) / f"n{n}-warm-up")
            for rep in range(a.repeat):
                pair = {}
                for shm in ((False, True) if rep % 2 == 0 else (True, False)):
                    r = one_run(n, shm, a, Path(tmp) / f"n{n}-{rep}-{int(shm)}")
                    pair[shm] = r
                    print(f"  {n:>3} robots, shared_memory {'on ' if shm else 'off'}: "
                          f"{r['private_mb_min']:.1f} / {r['private_mb_median']:.1f} / "
                          f"{r['private_mb_max']:.1f} MB ({r['robot_processes_sampled']} "
                          f"robots, {r['private_mb_sum']:.0f} MB in all), team "
                          f"{r['team_wall_s']} s, CPU {r['run_cpu_s']} s", flush=True)
                same = pair[False]["_rows"] == pair[True]["_rows"]
                print(f"       same links.csv (status, reason): {same}")
                for r in pair.values():
                    r.pop("_rows")
                    r["same_links_as_other"] = same
                    r["repeat"] = rep
                    records.append(r)
    load1 = os.getloadavg()
    print(f"load average {load0[0]:.1f} at the start, {load1[0]:.1f} at the end")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", {
        "args": vars(a),
        "load_start": load0, "load_end": load1, "cpu_count": os.cpu_count(),
        "records": records})
    print(f"saved {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
