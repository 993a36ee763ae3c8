"""The ``sync`` rule run by each robot alone (pipeline.consistency.sync_alone)."""

import numpy as np
from sync_instances import comm_edges, planted_instance

from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.sync import equip_sync
from pipeline.consistency.sync_alone import run_sync_locally
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import NetworkOptions


def test_a_restart_after_a_loss_keeps_the_teams_flood_graph():
    # robot 3 crashes; the others restart the rule without it, as equipped ("tree"), not
    # with equip_sync's default ("links")
    fpc, links, weight = planted_instance(3, 4, 3, 1.0, 0.8, False)
    robots, index = build_robots(fpc, links)
    for rb, li in zip(robots, index, strict=True):
        equip_sync(rb, weight[li], "tree")
    team = LocalTeam(len(fpc), comm_edges(links), NetworkOptions(crash_at={3: 5}, seed=1))
    runs = team.run(lambda end: run_sync_locally(robots[end.robot_id], end,
                                                 ProtocolOptions(reliable=True), len(fpc)))
    assert runs[3] is None
    assert [r.repeated_detections for r in runs[:3]] == [1, 1, 1]
    assert [rb.sync.flood for rb in robots[:3]] == ["tree"] * 3
    kept = np.zeros(len(links), dtype=bool)
    for rb, li in zip(robots[:3], index[:3], strict=True):
        kept[li] = rb.link_alive
    alive = links.cam_j != 3
    assert is_conflict_free(fpc, links.subset(kept & alive))
