"""Benchmark: the bytes a team of robot processes sends over Zenoh, plain vs compact.

Formation d (6 robots, 640x480, SIFT, the default command: evidence rule then fusion), and
with ``--twenty`` also a 20-robot ``ring2`` team, each run over ``--transport zenoh`` twice
in one run, alternating: ``plain`` (descriptors as extracted, float32, sent to every
neighbour; packets uncompressed: the encoding before) and ``compact`` (SIFT descriptors as
bytes, features only to the neighbour that matches with them, packets zlib-compressed:
:mod:`pipeline.matching.packed`, :mod:`pipeline.transport.wire`). Per stage (the feature
exchange, consistency, fusion): bytes counted (the algorithm messages as the simulator
counts them) and bytes handed to Zenoh (the encoded packets); totals, the ratio
compact / plain, wall time of the team, and whether ``links.csv`` is the same (statuses and
reasons) for both and for the simulator. Saves ``runs/bench-team-bytes/results.json``.

    .venv/bin/python bench/team_bytes.py [--twenty] [--repeat 1]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
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
from pipeline.team.assemble import stage_of_kind  # noqa: E402

STAGES = ("exchange", "consistency", "fusion")


def _run(cfg_kw: dict, out: Path, transport: str, wire: str | None = None) -> dict:
    from pipeline.progress import StageTimer
    from pipeline.runs.formation import FormationConfig, run_formation

    runs: list = []
    opts = {} if transport == "sim" else {"wire": wire, "keep_run": runs}
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the run's markdown report
        run_formation(FormationConfig(out=str(out), rerun=False, **cfg_kw),
                      StageTimer(verbose=False), transport=transport, **opts)
    wall = time.perf_counter() - t0
    rows = [tuple(line.split(",")[:6]) for line in (out / "links.csv").read_text().splitlines()]
    res = {"wall_s": wall, "rows": rows}
    if runs:
        res["team_s"] = runs[0].published_s
        report = json.loads((out / "report.json").read_text())
        robots = report["team"]["robots"].values()
        counted = dict.fromkeys(STAGES, 0)
        for r in robots:
            for k, v in r["bytes_by_kind"].items():
                counted[stage_of_kind(k)] += v
        on_wire = {s: sum(r["wire_bytes_by_stage"].get(s, 0) for r in robots)
                   for s in STAGES}
        res.update(counted=counted, wire=on_wire,
                   counted_total=sum(r["bytes"] for r in robots),
                   wire_total=sum(r["wire_bytes"] for r in robots),
                   conflictive_sets_after=report["after"]["conflictive_sets"])
    return res


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--twenty", action="store_true", help="also the 20-robot ring2 team")
    ap.add_argument("--repeat", type=count_argument, default=1, help="runs of each encoding (median wall)")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-team-bytes"))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    teams = {"d (6 robots)": dict(formation="d")}
    if args.twenty:
        teams["ring2 (20 robots)"] = dict(robots=20, graph="ring2")
    print(f"load average at the start: {os.getloadavg()[0]:.1f}")
    results = {"load_start": os.getloadavg()[0], "teams": {}}
    with tempfile.TemporaryDirectory(prefix="bench-bytes-") as tmp:
        tmp = Path(tmp)
        for name, kw in teams.items():
            sim = _run(kw, tmp / "sim", "sim")
            got = {"plain": [], "compact": []}
            for k in range(args.repeat):
                # alternating which goes first: the load of a shared machine drifts
                for wire in ("plain", "compact") if k % 2 == 0 else ("compact", "plain"):
                    got[wire].append(_run(kw, tmp / f"{wire}{k}", "zenoh", wire))
            team = {}
            for wire, runs in got.items():
                runs.sort(key=lambda r: r["team_s"])
                best = runs[len(runs) // 2]
                team[wire] = {k: v for k, v in best.items() if k != "rows"}
                team[wire]["team_walls_s"] = [round(r["team_s"], 2) for r in runs]
                team[wire]["links_same_as_sim"] = all(r["rows"] == sim["rows"] for r in runs)
            p, c = team["plain"], team["compact"]
            # the figure of the target: compact on the wire against the plain bytes counted
            team["compact_wire_over_plain_counted"] = c["wire_total"] / p["counted_total"]
            team["compact_wire_over_plain_wire"] = c["wire_total"] / p["wire_total"]
            results["teams"][name] = team
            mb = 1e6
            print(f"\n{name}: bytes per stage, MB (counted / handed to Zenoh)")
            print("| stage | plain | compact | compact / plain (wire) |")
            print("|---|---:|---:|---:|")
            for s in STAGES:
                print(f"| {s} | {p['counted'][s] / mb:.2f} / {p['wire'][s] / mb:.2f} | "
                      f"{c['counted'][s] / mb:.2f} / {c['wire'][s] / mb:.2f} | "
                      f"{c['wire'][s] / max(p['wire'][s], 1):.1%} |")
            print(f"| total | {p['counted_total'] / mb:.2f} / {p['wire_total'] / mb:.2f} | "
                  f"{c['counted_total'] / mb:.2f} / {c['wire_total'] / mb:.2f} | "
                  f"{c['wire_total'] / p['wire_total']:.1%} |")
            print(f"team wall (launch to last result, median): plain {p['team_s']:.2f} s "
                  f"{p['team_walls_s']}, compact {c['team_s']:.2f} s {c['team_walls_s']}; links.csv same as sim: plain "
                  f"{p['links_same_as_sim']}, compact {c['links_same_as_sim']}; conflictive "
                  f"sets after: {p['conflictive_sets_after']}, {c['conflictive_sets_after']}")
            print(f"compact on the wire / plain counted: "
                  f"{team['compact_wire_over_plain_counted']:.1%}")
    results["load_end"] = os.getloadavg()[0]
    print(f"\nload average at the end: {results['load_end']:.1f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", results)
    print(f"saved {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
