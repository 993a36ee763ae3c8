"""A toy resolution rule, registered on import: every robot of a conflictive set cuts its side
of every link of the set (both ends of such a link are conflictive, so cuts are symmetric
without a message). Used by test_rules.py through the registry, in this process and, named
in FORMATION_MATCH_RULES, in every robot process."""

import numpy as np

from pipeline.consistency.rules import ResolutionRule, register

CASE_TOY = 99


def _cut_set_links(robot) -> int:
    rows = np.flatnonzero(robot.link_alive & robot.conflictive[robot.link_r])
    robot.delete_links(rows, 0, CASE_TOY)
    return int(robot.conflictive.any())


def simulate(robots, network, protocol, iteration, on_round=None) -> dict:
    touched = sum(_cut_set_links(rb) for rb in robots)
    for rb in robots:
        finish(rb)
    return dict(rounds=0, conflictive_sets=touched)


def start(robot, rel, now) -> int:
    return _cut_set_links(robot)


def step(robot, rel, inbox, now, phase_round) -> None:
    rel.chan.receive(inbox, now)
    rel.chan.flush(now)


def done(robot, rel, lost_somewhere) -> bool:
    return rel.chan.idle()


def finish(robot) -> None:
    robot.candidates = robot.conflictive.copy()


TOY = register(ResolutionRule(
    name="toy", help="toy = cut every link of a conflictive set",
    title="detection (Sec. III) + the toy cut of every link of a conflictive set",
    summary="by the toy rule", cases={CASE_TOY: "toy"},
    simulate="toy_rule:simulate", start="toy_rule:start", step="toy_rule:step",
    done="toy_rule:done", finish="toy_rule:finish"))
