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

#: the environment of a configuration (FORMATION_MATCH_ZYGOTE: where the robots of each
#: team are forked from, pipeline.runs.transports.zenoh.ZYGOTE_ENV)
ENV = {"zenoh, zygote per team": {"FORMATION_MATCH_ZYGOTE": "team"}}


def _run(args: list[str], out: Path, env: dict | None = None) -> dict:
    """``python -m pipeline run-formation ARGS``: wall, report, links and steps tables."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pipeline", "run-formation", *args,
                           "--no-rerun", "--out", str(out)], cwd=ROOT,
                          env={**os.environ, "FORMATION_MATCH_ZYGOTE": "run", **(env or {})},
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
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-online-team"))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    import data_synth

    # refused by run-formation only once the bench had started (exit 1)
    data_synth.check_formation(args.formation)
    common = ["--steps", str(args.steps), "--formation", args.formation] + \
        ([] if args.size is None else ["--size", args.size])
    load = [round(x, 2) for x in os.getloadavg()]
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")
    runs: dict[str, list[dict]] = {k: [] for k in CONFIGS}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeat):
            for name, extra in CONFIGS.items():
                runs[name].append(_run(common + extra, Path(tmp) / f"{r}-{name}",
                                       ENV.get(name)))
    rows = {}
    for name, rs in runs.items():
        best = dict(sorted(rs, key=lambda x: x["wall_s"])[len(rs) // 2])
        best["walls_s"] = [x["wall_s"] for x in rs]
        ref = runs["sim --no-fusion" if "no-fusion" in name else "sim"][0]["tables"]
        best["tables_equal_sim"] = all(x["tables"] == ref for x in rs)
        del best["tables"]
        rows[name] = best
    print(f"run-formation {' '.join(common)} (--no-rerun), {args.repeat} run(s) each")
    print(f"{'':20s} {'wall s':>7s} {'online s':>8s} {'fusion s':>8s} {'cut':>12s} "
          f"{'tracks':>14s} {'fusion MB':>9s} {'naming MB':>9s} same")
    for name, r in rows.items():
        print(f"{name:20s} {r['wall_s']:7.2f} {r['online_s']:8.2f} {r['fusion_s']:8.2f} "
              f"{str(r['fusion_cut']):>12s} {str(r['fusion_tracks']):>14s} "
              f"{r['fusion_bytes'] / 1e6:9.2f} {r['naming_bytes'] / 1e6:9.2f} "
              f"{r['tables_equal_sim']}")
    for name, r in rows.items():
        print(f"{name:20s} each step's stage, s: {r['stage_s']}; matching, s: {r['match_s']}"
              + (f" ({r['match_bytes'] / 1e6:.2f} MB exchanged)" if r["match_bytes"] else ""))
    z, zn, s = rows["zenoh"]["wall_s"], rows["zenoh --no-fusion"]["wall_s"], rows["sim"]["wall_s"]
    sn = rows["sim --no-fusion"]["wall_s"]
    print(f"zenoh with fusion / zenoh --no-fusion: {z / zn:.2f}; zenoh / sim: {z / s:.2f}; "
          f"without fusion: {zn / sn:.2f}")
    zt = rows["zenoh, zygote per team"]
    print(f"zenoh, one zygote for the run's teams / a zygote per team: wall "
          f"{z / zt['wall_s']:.2f}, online stage {rows['zenoh']['online_s'] / zt['online_s']:.2f}")
    results = {"command": ["run-formation", *common, "--no-rerun"], "repeat": args.repeat,
               "cpus": os.cpu_count(), "load_average_at_start": load, "runs": rows}
    write_json_atomic(Path(args.out) / "results.json", results)
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
