"""Benchmark: the robots as objects of one process (sim) vs one process per robot (zenoh).

For formation d (6 robots) and a 20-robot formation, side by side in one run, each as a
command-line run (so process start is included on both sides): wall time, consistency and
fusion rounds, messages, bytes counted (the simulator's encoding) and bytes on the wire (zenoh
packets), peak RSS per process, whether ``links.csv`` is the same (statuses and reasons), and
for zenoh the time from ``kill -9`` of one robot during its fusion stage to the survivors'
finish, plus a run with message loss. Both sides run the default command (the evidence rule,
then fusion) and, for formation d, also ``--resolution paper`` (Alg. 1). For zenoh runs, the
robots' start profile: seconds from the launch of a robot process to entering the robot code
(interpreter and imports), to its Zenoh session being open, to the end of the start handshake
and to its result, median over the robots. Saves ``runs/bench-team/results.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

from pipeline.commands.options import count_argument, size_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

FORMATIONS = {"d (6 robots)": ["--formation", "d"],
              "ring2 (20 robots)": ["--robots", "20", "--graph", "ring2"]}


def _cli(args: list[str], out: Path) -> dict:
    return _cli_once(args, out)


def _median(runs: list[dict]) -> dict:
    """The run of median wall time, with every run's wall."""
    ordered = sorted(runs, key=lambda r: r["wall_s"])
    best = dict(ordered[len(ordered) // 2])
    best["walls_s"] = [round(r["wall_s"], 2) for r in runs]
    best["links_rows"] = runs[0]["links_rows"]
    return best


def _cli_once(args: list[str], out: Path) -> dict:
    """Run ``python -m pipeline run-formation ARGS`` and read its report; wall and RSS."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "pipeline", "run-formation", *args,
                             "--no-rerun", "--out", str(out)], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"run-formation {' '.join(args)} failed: {err[-500:]}")
    report = json.loads((out / "report.json").read_text())
    rows = [tuple(line.split(",")[:6]) for line in (out / "links.csv").read_text().splitlines()]
    return {"wall_s": wall, "report": report, "launcher_rss_bytes": usage.ru_maxrss * 1024,
            "links_rows": rows}


def _row(name: str, res: dict) -> dict:
    rep = res["report"]
    r = rep["resolution"]
    team = rep.get("team")
    row = {"run": name, "wall_s": round(res["wall_s"], 2), "walls_s": res.get("walls_s"),
           "rounds": int(r["detection_rounds"] + r["resolution_rounds"]),
           "messages": r["messages"], "bytes_counted": r["bytes"],
           "links_deleted": int(rep["before"]["links"] - rep["after"]["links"]),
           "fusion_rounds": rep["fusion"].get("rounds"),
           "fusion_messages": rep["fusion"].get("messages"),
           "fusion_bytes": rep["fusion"].get("bytes"),
           "fusion_cut": rep["fusion"].get("cut_links"),
           "conflictive_sets_after": rep["after"]["conflictive_sets"],
           "rss_launcher_mb": round(res["launcher_rss_bytes"] / 2**20, 1)}
    if team:
        rob = [v for v in team["robots"].values() if "rounds" in v]
        row["wire_bytes"] = sum(v["wire_bytes"] for v in rob)
        row["bytes_counted_all_kinds"] = sum(v["bytes"] for v in rob)
        row["rss_robot_max_mb"] = round(max(v["peak_rss_bytes"] for v in rob) / 2**20, 1)
        row["process_start_s"] = team["process_start_s"]
        row["team_wall_s"] = team["wall_s"]
        steps = [v.get("since_launch_s") or {} for v in rob]
        for k in ("entered", "session_open", "handshake_done", "main_done"):
            got = sorted(x[k] for x in steps if x.get(k) is not None)
            if got:
                row[f"start_{k}_s"] = round(got[len(got) // 2], 3)
    faults = rep.get("faults")
    if faults:
        row["links_cut_robot_lost"] = faults["links_cut_robot_lost"]
        row["messages_dropped"] = faults["messages_dropped"]
    return row


def _kill_run(args: list[str], size, out: Path) -> dict:
    """zenoh run with ``kill -9`` of robot 2 as its fusion stage starts."""
    from pipeline.commands.run_formation import add_arguments, config_from_args
    from pipeline.runs.formation import run_formation

    ap = argparse.ArgumentParser()
    add_arguments(ap)
    cfg = config_from_args(ap.parse_args([*args, "--no-rerun", "--size", size,
                                          "--out", str(out)]))
    runs = []
    t0 = time.perf_counter()
    run_formation(cfg, transport="zenoh", kill=(2, "fusion", 0.0), keep_run=runs)
    wall = time.perf_counter() - t0
    run = runs[0]
    rep = json.loads((out / "report.json").read_text())
    return {"wall_s": round(wall, 2),
            "kill_to_finish_s": round(max(run.finished_at.values()) - run.killed[2], 2),
            "survivors": sorted(run.results), "robots_lost": rep["faults"]["robots_lost"],
            "links_cut_robot_lost": rep["faults"]["links_cut_robot_lost"],
            "fusion_robots_lost": rep["fusion"].get("robots_lost"),
            "conflictive_sets_after": rep["after"]["conflictive_sets"]}


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--size", default="640x480", type=size_argument)
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-team"))
    ap.add_argument("--only", default=None, help="run one formation key only")
    ap.add_argument("--repeat", type=count_argument, default=3,
                    help="runs of each sim/zenoh configuration, the median wall kept "
                         "(default 3; the machine may be shared)")
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    if args.only is not None and not any(args.only in name for name in FORMATIONS):
        ap.error(f"--only {args.only!r}: no formation key holds it; the keys are "
                 + ", ".join(repr(name) for name in FORMATIONS))
    load = [round(x, 2) for x in os.getloadavg()]
    results = {"size": args.size, "formations": {}, "cpus": os.cpu_count(),
               "load_average_at_start": load}
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for k, (name, fargs) in enumerate(FORMATIONS.items()):
            if args.only and args.only not in name:
                continue
            # the default resolution (evidence rule) on both sides, side by side
            base = [*fargs, "--size", args.size]
            rows, same = [], {}
            # alternate the two sides so that a busy spell of the machine hits both
            sim_runs, zen_runs = [], []
            for r in range(args.repeat):
                sim_runs.append(_cli_once(base, tmp / f"s{k}-{r}"))
                zen_runs.append(_cli_once([*base, "--transport", "zenoh"], tmp / f"z{k}-{r}"))
            sim_med, zen_med = _median(sim_runs), _median(zen_runs)
            same["default"] = sim_med["links_rows"] == zen_med["links_rows"]
            rows.append(_row("sim", sim_med))
            rows.append(_row("zenoh", zen_med))
            if k == 0:
                paper = [*base, "--resolution", "paper"]
                sim_runs, zen_runs = [], []
                for r in range(args.repeat):
                    sim_runs.append(_cli_once(paper, tmp / f"sp{k}-{r}"))
                    zen_runs.append(_cli_once([*paper, "--transport", "zenoh"],
                                              tmp / f"zp{k}-{r}"))
                sim_med, zen_med = _median(sim_runs), _median(zen_runs)
                same["paper"] = sim_med["links_rows"] == zen_med["links_rows"]
                rows.append(_row("sim paper", sim_med))
                rows.append(_row("zenoh paper", zen_med))
            rows.append(_row("zenoh --drop-prob 0.2",
                             _cli([*base, "--transport", "zenoh", "--drop-prob", "0.2"],
                                  tmp / f"zd{k}")))
            kill = _kill_run(fargs, args.size, tmp / f"zk{k}")
            sim = next(r for r in rows if r["run"] == "sim")
            zen = next(r for r in rows if r["run"] == "zenoh")
            results["formations"][name] = {
                "rows": rows, "kill_9": kill,
                "zenoh_over_sim_wall": round(zen["wall_s"] / sim["wall_s"], 2),
                "same_links_csv": same}
            if k == 0:
                sp = next(r for r in rows if r["run"] == "sim paper")
                zp = next(r for r in rows if r["run"] == "zenoh paper")
                results["formations"][name]["zenoh_over_sim_wall_paper"] = round(
                    zp["wall_s"] / sp["wall_s"], 2)
            print(f"\n== formation {name}, {args.size}")
            cols = ["run", "wall_s", "rounds", "messages", "bytes_counted", "fusion_rounds",
                    "fusion_messages", "fusion_bytes", "bytes_counted_all_kinds", "wire_bytes",
                    "rss_launcher_mb", "rss_robot_max_mb", "links_deleted", "fusion_cut",
                    "conflictive_sets_after", "links_cut_robot_lost"]
            print(" | ".join(f"{c:>14}" for c in cols))
            for r in rows:
                print(" | ".join(f"{str(r.get(c, '-')):>14}" for c in cols))
            print(f"links.csv the same over both transports (statuses, reasons): {same}")
            print(f"kill -9 of robot 2 in its fusion stage: survivors {kill['survivors']} finished "
                  f"{kill['kill_to_finish_s']} s after the kill; {kill['links_cut_robot_lost']} "
                  f"links cut robot-lost; conflictive sets after: {kill['conflictive_sets_after']}")
            prof = ["start_entered_s", "start_session_open_s", "start_handshake_done_s",
                    "start_main_done_s", "team_wall_s"]
            print("zenoh robot start, median seconds since launch: " + "; ".join(
                f"{r['run']}: " + ", ".join(f"{c[6:-2] if c.startswith('start_') else c[:-2]} "
                                            f"{r.get(c, '-')}" for c in prof)
                for r in rows if r["run"].startswith("zenoh")))
            ratio = results["formations"][name]["zenoh_over_sim_wall"]
            print(f"walls (s), sim: {sim['walls_s']}, zenoh: {zen['walls_s']}")
            print(f"zenoh / sim wall time (default run: evidence rule, fusion): {ratio}x "
                  f"(target <= 3x: {'met' if ratio <= 3 else 'NOT met'})")
            if k == 0:
                print("zenoh / sim wall time with --resolution paper: "
                      f"{results['formations'][name]['zenoh_over_sim_wall_paper']}x")
    results["load_average_at_end"] = [round(x, 2) for x in os.getloadavg()]
    print(f"load average at the end (1, 5, 15 min): {results['load_average_at_end']}")
    write_json_atomic(Path(args.out) / "results.json", results)
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
