"""A robot alone repeats the detection after any phase in which some robot lost a neighbour
(termination.py, "Phases"): a detection whose blocks may have come through the lost robot is
not trusted, and a closing that lost a robot ends nothing."""

import numpy as np
import pytest
from consistency_graphs import random_instance

from pipeline.commgraph import comm_edges_for
from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.termination import run_consistency_locally
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import NetworkOptions


def _phases_after_a_crash(crash_round):
    fpc, edges, links = random_instance(np.random.default_rng(5), 6, 5, 1.0, 0.9)
    edges = comm_edges_for(fpc, links, edges)
    robots, link_index = build_robots(fpc, links)
    team = LocalTeam(len(fpc), edges, NetworkOptions(crash_at={2: crash_round}))
    logs = team.run(lambda tr: run_consistency_locally(robots[tr.robot_id], tr,
                                                       resolution="paper"))
    deleted = np.zeros(len(links), dtype=bool)
    for rb, li in zip(robots, link_index, strict=True):
        if team.network.alive(rb.id):
            deleted[li[~rb.link_alive]] = True
    alive = np.arange(len(fpc)) != 2
    assert is_conflict_free(fpc, links.subset(~deleted & alive[links.cam_i] & alive[links.cam_j]))
    return [lg.phases for lg in logs if lg is not None], logs[2] is None


@pytest.mark.parametrize("crash_round", [3, 12, 27, 35, 60])
def test_every_phase_that_lost_a_robot_is_followed_by_a_detection(crash_round):
    lost_phases = 0
    seen = set()
    survivors, crashed = _phases_after_a_crash(crash_round)
    for phases in survivors:
        for now, nxt in zip(phases, phases[1:] + [None], strict=True):
            if now["phase"] in ("detection", "closing") and now["lost_somewhere"]:
                seen.add(now["phase"])
                lost_phases += 1
                assert nxt is not None and nxt["phase"] == "detection", (now, nxt)
                assert nxt["iteration"] == now["iteration"]
        # the run ends on a closing that lost nobody
        assert phases[-1]["phase"] == "closing" and not phases[-1]["lost_somewhere"]
    # round 3: in the first detection; round 27: after the last detection, before the close
    # (noticed by the closing phase); round 35: after confirming the close (kept, not lost)
    if crash_round in (3, 27):
        assert crashed and seen == {"detection" if crash_round == 3 else "closing"}
