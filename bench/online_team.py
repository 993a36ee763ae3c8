"""Benchmark: an online run (``run-formation --steps N``) on the simulator and over Zenoh, with
and without the fusion of each step's changed tracks, side by side in one run.

Each configuration is a command-line run (process start included): ``sim``, ``sim
--no-fusion``, ``zenoh --no-fusion`` and ``zenoh`` (fusion on: one robot process per frame of
the changed tracks each step, :func:`pipeline.runs.transports.zenoh.online_fusion`), and
``zenoh`` again with every team forking its robots from a zygote of its own
(``FORMATION_MATCH_ZYGOTE=team``; the others share one zygote for the run's teams), on the
same formation, alternated ``--repeat`` times (the median wall kept). Printed and saved per
configuration: wall time, the online stage's time, the fusion's time summed over the steps
(``fusion.wall_s`` of each step, team start included over Zenoh), links cut by fusion, tracks
fused, fusion bytes counted, the bytes the robots spent naming their tracks (over Zenoh, a
detection before the fusion), each step's stage time (matching and fusion not included),
each step's matching time (over Zenoh the robots' own, :mod:`pipeline.team.online_match`)
and the bytes its robots exchanged, and whether ``links.csv`` and ``link_steps.csv`` equal
the simulator's with the same fusion setting. Saves ``runs/bench-online-team/results.json``.

``zenoh, robots killed`` is ``zenoh`` with a robot process killed (``kill -9``, the fault
injection of :func:`pipeline.team.launcher.launch_team`) in each team of step
``--kill-step``: its matching's, its stage's and its fusion's robot 0, as soon as it starts
(the matching) or starts its consistency stage. Each such team is started again
(:mod:`pipeline.runs.online`, "Robot processes lost"): the tables must equal the
simulator's, and the step's record counts the attempts (printed: ``match_attempts``,
``stage_attempts``, the fusion's lost frames per step).

``zenoh, robot 0 lost for good`` is ``zenoh`` with robot 0's matching process killed as
soon as it starts in every team of every step from ``--kill-step`` on, the team started
again included (its camera's frames never arrive: a host gone for good). The mission goes on
without them (each such frame void, :func:`pipeline.runs.transports.zenoh.online_match`);
printed: the void frames per step, the pairwise F1 against ``zenoh``'s and what the second
team of each step costs. Its teams of the stage and fusion are not touched: they hold robot
0's frames from before ``--kill-step``, which a host gone for good would lose too.

``zenoh, hosts in namespaces, 1mbit cables`` is ``zenoh`` with every robot of every team on a
host of its own: a Linux network namespace, one cable per comm edge of its team, each capped
at 1 Mbit/s (``FORMATION_MATCH_HOSTS=netns:1mbit``, :func:`pipeline.team.netns.
launch_team_on_hosts`; each robot its own interpreter, not forked from a zygote). It needs
root and iproute2: where network namespaces cannot be made, the bench says why and leaves
that configuration out.
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

CONFIGS = {"sim": [], "sim --no-fusion": ["--no-fusion"],
           "zenoh --no-fusion": ["--transport", "zenoh", "--no-fusion"],
           "zenoh": ["--transport", "zenoh"],
           "zenoh, zygote per team": ["--transport", "zenoh"]}

KILLED = "zenoh, robots killed"
CONFIGS[KILLED] = ["--transport", "zenoh"]
LOST = "zenoh, robot 0 lost for good"
CONFIGS[LOST] = ["--transport", "zenoh"]

HOSTS = "zenoh, hosts in namespaces, 1mbit cables"
CONFIGS[HOSTS] = ["--transport", "zenoh"]

#: the environment of a configuration (FORMATION_MATCH_ZYGOTE: where the robots of each
#: team are forked from, pipeline.runs.transports.zenoh.ZYGOTE_ENV; FORMATION_MATCH_HOSTS:
#: where they run, pipeline.runs.transports.zenoh.HOSTS_ENV)
ENV = {"zenoh, zygote per team": {"FORMATION_MATCH_ZYGOTE": "team"},
       HOSTS: {"FORMATION_MATCH_HOSTS": "netns:1mbit"}}

#: what every configuration runs with unless ENV says otherwise (not the caller's settings)
BASE_ENV = {"FORMATION_MATCH_ZYGOTE": "run", "FORMATION_MATCH_HOSTS": "loopback"}


def _killing_child(step: int, argv: list[str]) -> int:
    """``run-formation ARGV`` (over Zenoh) with robot 0 of each team of step ``step`` killed:
    the matching's as soon as it starts, the stage's and the fusion's as soon as they start
    their consistency stage (module docstring)."""
    import pipeline.runs.transports.zenoh as zenoh
    from pipeline.__main__ import main as command

    now = {"step": -1, "stage": 0, "fusion": 0}
    match, stage, fusion = zenoh.online_match, zenoh.online_stage, zenoh.online_fusion

    def killing_match(views, t, *a, **kw):
        now.update(step=int(t), stage=0, fusion=0)
        if t == step:
            kw["kill"] = (0, "started", 0.0)
        return match(views, t, *a, **kw)

    def once(job, key):
        def wrapped(*a, **kw):
            now[key] += 1
            if now["step"] == step and now[key] == 1:
                kw["kill"] = (0, "consistency", 0.0)
            return job(*a, **kw)
        return wrapped

    zenoh.online_match = killing_match
    zenoh.online_stage = once(stage, "stage")
    zenoh.online_fusion = once(fusion, "fusion")
    return command(argv)


def _losing_child(step: int, argv: list[str]) -> int:
    """``run-formation ARGV`` (over Zenoh) with robot 0's matching process killed as soon as
    it starts in every team of every step from ``step`` on, the team started again included:
    its camera's frames never reach the others (module docstring)."""
    import pipeline.runs.transports.zenoh as zenoh
    from pipeline.__main__ import main as command

    match = zenoh.online_match

    def losing_match(views, t, *a, **kw):
        if t >= step:
            kw["kill"] = [(0, "started", 0.0), (0, "started", 0.0)]
        return match(views, t, *a, **kw)

    zenoh.online_match = losing_match
    return command(argv)


def _run(args: list[str], out: Path, env: dict | None = None,
         kill_step: int | None = None, lost_step: int | None = None) -> dict:
    """``python -m pipeline run-formation ARGS`` (with ``kill_step``: robots killed at that
    step, :func:`_killing_child`; with ``lost_step``: robot 0 lost for good from that step,
    :func:`_losing_child`): wall, report, links and steps tables."""
    t0 = time.perf_counter()
    head = [sys.executable, "-m", "pipeline"]
    if kill_step is not None:
        head = [sys.executable, str(Path(__file__).resolve()), "--killing-child", str(kill_step)]
    elif lost_step is not None:
        head = [sys.executable, str(Path(__file__).resolve()), "--losing-child", str(lost_step)]
    proc = subprocess.run([*head, "run-formation", *args,
                           "--no-rerun", "--out", str(out)], cwd=ROOT,
                          env={**os.environ, **BASE_ENV, **(env or {})},
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"run-formation {' '.join(args)} failed: "
                           f"{proc.stderr.decode(errors='replace')[-500:]}")
    rep = json.loads((out / "report.json").read_text())
    steps = rep["steps"]
    fus = [s.get("fusion") or {} for s in steps]
    return {"wall_s": round(wall, 2),
            "online_s": round(rep["timings_s"].get("online", 0.0), 2),
            "fusion_s": round(sum(f.get("wall_s", 0.0) for f in fus), 2),
            # each step's stage (the step record's wall_s: matching and fusion not included):
            # over Zenoh, the step's team of robot processes
            "stage_s": [round(s["wall_s"], 2) for s in steps],
            # each step's matching (over Zenoh the robots' own, a team per step)
            "match_s": [round(s["match_s"], 2) for s in steps],
            "match_bytes": sum(s.get("match_bytes", 0) for s in steps),
            "fusion_cut": [f.get("cut") for f in fus],
            "fusion_tracks": [f.get("tracks") for f in fus],
            "fusion_bytes": sum(f.get("bytes", 0) for f in fus),
            "naming_bytes": sum(f.get("naming_bytes", 0) for f in fus),
            "links": len(rep["steps"]) and int(steps[-1]["links_total"]),
            # teams started per step (1 each without a loss)
            "match_attempts": [s.get("match_attempts", 1) for s in steps],
            "stage_attempts": [s.get("stage_attempts", 0) for s in steps],
            "fusion_frames_lost": [len(f.get("frames_lost", ())) for f in fus],
            "frames_void": [s.get("match_frames_void", []) for s in steps],
            "f1": rep["final"]["online"]["f1"],
            "tables": [(out / n).read_text() for n in ("links.csv", "link_steps.csv")]}


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--formation", default="d")
    ap.add_argument("--steps", type=count_argument, default=3)
    ap.add_argument("--size", default=None, type=size_argument,
                    help="WxH (default: the command's)")
    ap.add_argument("--repeat", type=count_argument, default=1,
                    help="runs of each configuration, alternated; the median wall kept")
    ap.add_argument("--kill-step", type=int, default=1,
                    help="the step whose teams lose robot 0 in the 'zenoh, robots killed' "
                         "configuration, and from which robot 0 is lost for good in 'zenoh, "
                         "robot 0 lost for good' (module docstring; default 1)")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-online-team"))
    args = ap.parse_args(argv)
    if not 0 <= args.kill_step < args.steps:
        ap.error(f"--kill-step {args.kill_step}: a step of the run, 0 to {args.steps - 1}")
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    import data_synth

    # refused by run-formation only once the bench had started (exit 1)
    data_synth.check_formation(args.formation)
    from pipeline.team.netns import unavailable

    configs = dict(CONFIGS)
    if (why := unavailable()) is not None:
        print(f"{HOSTS}: left out, no network namespaces here ({why})")
        del configs[HOSTS]
    common = ["--steps", str(args.steps), "--formation", args.formation] + \
        ([] if args.size is None else ["--size", args.size])
    load = [round(x, 2) for x in os.getloadavg()]
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")
    runs: dict[str, list[dict]] = {k: [] for k in configs}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeat):
            for name, extra in configs.items():
                runs[name].append(_run(common + extra, Path(tmp) / f"{r}-{name}",
                                       ENV.get(name),
                                       args.kill_step if name == KILLED else None,
                                       args.kill_step if name == LOST else None))
    rows = {}
    for name, rs in runs.items():
        best = dict(sorted(rs, key=lambda x: x["wall_s"])[len(rs) // 2])
        best["walls_s"] = [x["wall_s"] for x in rs]
        ref = runs["sim --no-fusion" if "no-fusion" in name else "sim"][0]["tables"]
        best["tables_equal_sim"] = all(x["tables"] == ref for x in rs)
        del best["tables"]
        rows[name] = best
    print(f"run-formation {' '.join(common)} (--no-rerun), {args.repeat} run(s) each")
    w = max(20, *(len(name) for name in rows))  # the names' column
    print(f"{'':{w}s} {'wall s':>7s} {'online s':>8s} {'fusion s':>8s} {'cut':>12s} "
          f"{'tracks':>14s} {'fusion MB':>9s} {'naming MB':>9s} same")
    for name, r in rows.items():
        print(f"{name:{w}s} {r['wall_s']:7.2f} {r['online_s']:8.2f} {r['fusion_s']:8.2f} "
              f"{str(r['fusion_cut']):>12s} {str(r['fusion_tracks']):>14s} "
              f"{r['fusion_bytes'] / 1e6:9.2f} {r['naming_bytes'] / 1e6:9.2f} "
              f"{r['tables_equal_sim']}")
    for name, r in rows.items():
        print(f"{name:{w}s} each step's stage, s: {r['stage_s']}; matching, s: {r['match_s']}"
              + (f" ({r['match_bytes'] / 1e6:.2f} MB exchanged)" if r["match_bytes"] else ""))
    z, zn, s = rows["zenoh"]["wall_s"], rows["zenoh --no-fusion"]["wall_s"], rows["sim"]["wall_s"]
    sn = rows["sim --no-fusion"]["wall_s"]
    print(f"zenoh with fusion / zenoh --no-fusion: {z / zn:.2f}; zenoh / sim: {z / s:.2f}; "
          f"without fusion: {zn / sn:.2f}")
    zt = rows["zenoh, zygote per team"]
    print(f"zenoh, one zygote for the run's teams / a zygote per team: wall "
          f"{z / zt['wall_s']:.2f}, online stage {rows['zenoh']['online_s'] / zt['online_s']:.2f}")
    k = rows[KILLED]
    print(f"{KILLED} at step {args.kill_step}: teams started per step: matching "
          f"{k['match_attempts']}, stage {k['stage_attempts']}, fusion frames lost "
          f"{k['fusion_frames_lost']}; the same tables as the simulator: "
          f"{k['tables_equal_sim']}; wall / zenoh's {k['wall_s'] / z:.2f}, step "
          f"{args.kill_step}'s stage {k['stage_s'][args.kill_step]:.2f} s against "
          f"{rows['zenoh']['stage_s'][args.kill_step]:.2f} s, its matching "
          f"{k['match_s'][args.kill_step]:.2f} s against "
          f"{rows['zenoh']['match_s'][args.kill_step]:.2f} s")
    lo = rows[LOST]
    print(f"{LOST} from step {args.kill_step}: frames void per step {lo['frames_void']}, "
          f"teams started per step: matching {lo['match_attempts']}; pairwise F1 "
          f"{lo['f1']:.4f} against zenoh's {rows['zenoh']['f1']:.4f} (on the frames each "
          f"association had); wall / zenoh's {lo['wall_s'] / z:.2f}, step {args.kill_step}'s "
          f"matching {lo['match_s'][args.kill_step]:.2f} s against "
          f"{rows['zenoh']['match_s'][args.kill_step]:.2f} s")
    if HOSTS in rows:
        h = rows[HOSTS]
        print(f"{HOSTS}: the same tables as the simulator: {h['tables_equal_sim']}; wall / "
              f"zenoh's {h['wall_s'] / z:.2f}, online stage / zenoh's "
              f"{h['online_s'] / rows['zenoh']['online_s']:.2f}, fusion / zenoh's "
              f"{h['fusion_s'] / rows['zenoh']['fusion_s']:.2f}")
    results = {"command": ["run-formation", *common, "--no-rerun"], "repeat": args.repeat,
               "kill_step": args.kill_step,
               "cpus": os.cpu_count(), "load_average_at_start": load, "runs": rows}
    write_json_atomic(Path(args.out) / "results.json", results)
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--killing-child"]:
        raise SystemExit(_killing_child(int(sys.argv[2]), sys.argv[3:]))
    if sys.argv[1:2] == ["--losing-child"]:
        raise SystemExit(_losing_child(int(sys.argv[2]), sys.argv[3:]))
    raise SystemExit(main())
