"""``python -m pipeline observe --team TEAM.json --out DIR``: the run folder of a team whose
robots run elsewhere (started by hand with ``formation-match robot``, on one machine or
several).

The observer listens on the team file's ``observer`` endpoint, collects every robot's
published result and writes the run folder the one-machine launcher writes for the same team
(:mod:`pipeline.runs.observe`). Start it before or with the robots: each robot repeats its
result until the observer acknowledges it, for up to ``start_timeout_s`` of the team options.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--team", required=True, metavar="TEAM.json",
                   help="team file with an 'observer' endpoint (see README, Transports)")
    p.add_argument("--out", required=True, help="run folder to write")
    p.add_argument("--timeout", type=float, default=600.0, metavar="S",
                   help="give up on robots that have not ended after S seconds (default 600); "
                        "those that did not publish are reported lost")
    p.add_argument("--no-rerun", action="store_true", help="do not write recording.rrd")


def run(args) -> int:
    import json
    import sys

    from pipeline.errors import InputError
    from pipeline.outcome import exit_status
    from pipeline.runfolder import claim_run_folder
    from pipeline.runs.observe import observe_run
    from pipeline.team.teamfile import MAX_TIMEOUT_S
    from pipeline.validate import not_empty, shown

    if not 0 < args.timeout <= MAX_TIMEOUT_S:
        raise InputError(f"--timeout {shown(args.timeout)} must be a number of seconds in "
                         f"(0, {MAX_TIMEOUT_S:g}]")
    from pipeline.team.teamfile import load_team

    start = float(load_team(args.team).options.get("start_timeout_s", 0))
    if args.timeout < start:
        print(f"warning: --timeout {args.timeout:g} s is shorter than the team's start_timeout_s "
              f"({start:g} s): robots still waiting for a neighbour when the observer gives up "
              "publish to no one", file=sys.stderr)
    not_empty(args.out, "--out")  # not the current folder
    with claim_run_folder(args.out, [("--team", args.team)]):
        out = observe_run(args.team, args.out, timeout_s=args.timeout,
                          rerun=not args.no_rerun,
                          log=lambda s: print(s, file=sys.stderr, flush=True))
    report = json.loads((out / "report.json").read_text())
    print(f"run written to {out}/")
    return exit_status(report)
