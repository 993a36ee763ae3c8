"""The fusion stage of robots alone over the reliable channel, on a lossy network, with a
robot that crashes at any round: every other robot finishes, and a neighbour that lost it
says so (robot_loops.run_fusion_reliably: a neighbour silent for ``T`` rounds while expected
is declared lost, whichever logical round it fell silent in, its last included). The threads'
drops are keyed by the message (LocalTeam), so each seed's run is the same on every
interleaving."""

import sys
from pathlib import Path

from pipeline.fusion.robot_loops import run_fusion_reliably
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import NetworkOptions

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_robot import _ring_rig, _robots  # noqa: E402


def test_a_crash_at_any_round_leaves_the_others_finishing():
    views, feats, links, edges, labels = _ring_rig()
    crashed_in_run = 0
    for r in range(1, 40, 2):
        robots = _robots(views, feats, edges, labels)
        team = LocalTeam(len(views), edges,
                         NetworkOptions(drop_probability=0.2, seed=r, crash_at={3: r}))
        outs = team.run(lambda end, robots=robots: run_fusion_reliably(robots[end.id], end))
        assert all(outs[i] is not None and robots[i].done for i in range(6) if i != 3), r
        if outs[3] is None:
            crashed_in_run += 1
            assert all(outs[i]["lost"] in ([], [3]) for i in (2, 4)), r
    assert crashed_in_run >= 3
