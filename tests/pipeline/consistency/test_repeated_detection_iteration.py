"""A detection repeated after a robot was lost stays in its iteration: the cuts of the
resolution that follows carry the same iteration number as the report's ``iterations`` and
``per_iteration`` records, on the simulator and on a robot run alone (the process team's)."""

import numpy as np
from consistency_graphs import random_instance

from pipeline.consistency import resolve_conflicts
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.termination import run_consistency_locally
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import NetworkOptions


def _instance():
    return random_instance(np.random.default_rng(3), 6, 5, 0.6, 0.9)


def _crashed_during_the_first_detection():
    fpc, edges, links = _instance()
    proto = ProtocolOptions()
    proto.reliable = True
    for k in range(len(fpc)):
        res = resolve_conflicts(fpc, edges, links, NetworkOptions(crash_at={k: 2}),
                                protocol=proto, resolution="paper")
        per = res.stats["per_iteration"]
        if per[0].get("repeated") and (res.reason == "resolution").any():
            return res, k
    raise AssertionError("no crash repeats the first detection and leaves a cut")


def test_cuts_after_a_repeated_detection_carry_the_counted_iteration():
    res, _ = _crashed_during_the_first_detection()
    st = res.stats
    cut = res.reason == "resolution"
    resolved = [p["iteration"] for p in st["per_iteration"]
                if p["conflictive_features"] > 0 and not p.get("repeated")]
    assert len(resolved) == st["iterations"]
    assert resolved == list(range(1, st["iterations"] + 1))
    assert set(res.iteration[cut].tolist()) <= set(resolved)
    assert st["per_iteration"][0]["iteration"] == 1 and st["per_iteration"][1]["iteration"] == 1


def test_a_robot_alone_numbers_its_cuts_as_the_simulator():
    res, k = _crashed_during_the_first_detection()
    fpc, edges, links = _instance()
    robots, _ = build_robots(fpc, links)
    team = LocalTeam(len(fpc), edges, NetworkOptions(crash_at={k: 2}))
    logs = team.run(lambda tr: run_consistency_locally(robots[tr.robot_id], tr,
                                                       resolution="paper"))
    for rb, lg in zip(robots, logs, strict=True):
        if not team.network.alive(rb.id) or lg is None:
            continue
        cut = rb.deleted_iteration[rb.deleted_iteration > 0]
        assert set(cut.tolist()) <= set(range(1, lg.iterations + 1)), rb.id
        resolved = [p["iteration"] for p in lg.phases if p["phase"] == "resolution"]
        assert resolved == list(range(1, lg.iterations + 1)), rb.id
