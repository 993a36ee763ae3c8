"""``python -m pipeline robot --team TEAM.json --id I``: run one robot of a team.

The robot listens on its endpoint of the team file, connects to its comm-graph neighbours,
and runs features, matching, detection and resolution with them over Zenoh
(:mod:`pipeline.team.robot`). Start one per robot, on one machine or several; the robots wait
for each other (``start_timeout_s`` of the team options) and name any that never answers.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--team", required=True, metavar="TEAM.json",
                   help="team file: robots, endpoints, comm graph, data (see README)")
    p.add_argument("--id", required=True, help="this robot's id in the team (0..n-1)")
    p.add_argument("--result", default=None, metavar="JSON",
                   help="also write this robot's result (counters, its links and their "
                        "status) to a JSON file")
    p.add_argument("--overwrite", action="store_true",
                   help="replace --result if it exists (default: refuse)")


def run(args) -> int:
    import sys

    from pipeline.outputs import check_output_files
    from pipeline.team.robot import run_robot_process
    from pipeline.team.teamfile import check_data_files, load_team
    from pipeline.transport import NO_NEIGHBOUR_EXIT, RobotMissingError

    team = load_team(args.team)
    i = team.check_id(args.id)
    # everything this robot reads and writes is checked before its session opens
    inputs = check_data_files(team, i)
    check_output_files([("--result", args.result)], [("--team", args.team), *inputs],
                       overwrite=args.overwrite)
    try:
        code = run_robot_process(team, i, args.result, overwrite=args.overwrite)
    except RobotMissingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return NO_NEIGHBOUR_EXIT
    return code
