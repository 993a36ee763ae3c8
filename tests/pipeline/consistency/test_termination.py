"""Local termination (termination wave): robots as threads end every phase by themselves and
reach the simulator driver's decisions."""

import numpy as np
import pytest
from consistency_graphs import instances, random_instance
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.commgraph import comm_edges_for
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.termination import TerminationWave, run_consistency_locally
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import NetworkOptions


def _run_team(fpc, edges, links, options=None):
    robots, link_index = build_robots(fpc, links)
    team = LocalTeam(len(fpc), edges, options)
    logs = team.run(lambda tr: run_consistency_locally(robots[tr.robot_id], tr, resolution="paper"))
    deleted = np.zeros(len(links), dtype=bool)
    for rb, li in zip(robots, link_index, strict=True):
        if team.network.alive(rb.id):
            deleted[li[~rb.link_alive]] = True
    return deleted, logs, team


@settings(max_examples=25, deadline=None)
@given(instances())
def test_local_termination_gives_the_drivers_links(inst):
    fpc, edges, links = inst
    edges = comm_edges_for(fpc, links, edges)
    ref = resolve_conflicts(fpc, edges, links, resolution="paper")
    deleted, logs, _ = _run_team(fpc, edges, links)
    assert np.array_equal(deleted, ref.deleted)
    # every robot ran the same phase sequence, ending each phase at the same round
    starts = {tuple((p["phase"], p["start_round"], p["rounds"]) for p in lg.phases)
              for lg in logs}
    comps = _components(len(fpc), edges)
    assert len(starts) <= comps


def _components(n, edges):
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.asarray(edges).reshape(-1, 2)
    a = csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(a, directed=False)[0]


def test_phase_ends_n_minus_1_rounds_after_the_last_robot_is_done():
    """Hand-checked wave on a line 0-1-2 (n = 3): robot 2 is done from round 4 on, the others
    from round 1; every robot sees c >= 3 first at round 4 + 3 - 1 = 6."""
    n = 3
    nbrs = {0: [1], 1: [0, 2], 2: [1]}
    done_from = {0: 1, 1: 1, 2: 4}
    waves = {i: TerminationWave(n) for i in range(n)}
    for i in range(n):
        waves[i].start(False, 0)
    ended = {}
    for t in range(1, 12):
        states = {i: waves[i].state() for i in range(n)}
        for i in range(n):
            if waves[i].update(t >= done_from[i], 0, {k: states[k] for k in nbrs[i]}):
                ended.setdefault(i, t)
    assert ended == {0: 6, 1: 6, 2: 6}


def test_wave_does_not_end_while_a_far_robot_is_busy_again():
    """Robots that are done and woken again (resolution) keep everyone in the phase.

    Some robot is busy in every round up to 7 (as when a request chain travels from one end of
    the line to the other and back), so there is no round at which all are done before 8.
    """
    n = 4
    nbrs = {0: [1], 1: [0, 2], 2: [1, 3], 3: [2]}
    busy = {3: {1, 2, 3, 7}, 0: {4, 5, 6}}
    waves = {i: TerminationWave(n) for i in range(n)}
    for i in range(n):
        waves[i].start(False, 0)
    ended = {}
    for t in range(1, 20):
        states = {i: waves[i].state() for i in range(n)}
        for i in range(n):
            done = t not in busy.get(i, ())
            if waves[i].update(done, 0, {k: states[k] for k in nbrs[i]}):
                ended.setdefault(i, t)
    assert set(ended.values()) == {7 + n}  # last busy round 7: all end at 8 + n - 1


def test_or_bits_reach_every_robot():
    n = 4
    nbrs = {0: [1], 1: [0, 2], 2: [1, 3], 3: [2]}
    waves = {i: TerminationWave(n) for i in range(n)}
    for i in range(n):
        waves[i].start(True, 1 if i == 3 else 0)
    for _t in range(1, 10):
        states = {i: waves[i].state() for i in range(n)}
        ends = [waves[i].update(True, 1 if i == 3 else 0, {k: states[k] for k in nbrs[i]})
                for i in range(n)]
        if all(ends):
            break
    assert all(ends) and all(waves[i].bits == 1 for i in range(n))


@pytest.mark.parametrize("p", [0.2, 0.5])
def test_local_termination_under_loss_ends_conflict_free(p):
    fpc, edges, links = random_instance(np.random.default_rng(3), 6, 5, 0.6, 0.9)
    edges = comm_edges_for(fpc, links, edges)
    deleted, logs, team = _run_team(fpc, edges, links, NetworkOptions(drop_probability=p, seed=2))
    assert team.network.dropped > 0
    assert is_conflict_free(fpc, links.subset(~deleted))
    assert not any(lg.lost_neighbours for lg in logs)  # loss costs rounds, never a robot


def test_local_termination_with_a_crash_ends_conflict_free():
    fpc, edges, links = random_instance(np.random.default_rng(5), 6, 5, 1.0, 0.9)
    edges = comm_edges_for(fpc, links, edges)
    deleted, logs, team = _run_team(fpc, edges, links, NetworkOptions(crash_at={2: 3}))
    assert logs[2] is None
    alive = np.array([i != 2 for i in range(len(fpc))])
    kept = links.subset(~deleted & alive[links.cam_i] & alive[links.cam_j])
    assert is_conflict_free(fpc, kept)
    assert all(2 in lg.lost_neighbours for i, lg in enumerate(logs)
               if lg is not None and i in {int(k) for e in edges for k in e if 2 in e})


def _run_team_evidence(fpc, edges, links, weight, options=None, budget=None):
    from pipeline.consistency.evidence import equip

    robots, link_index = build_robots(fpc, links)
    for rb, li in zip(robots, link_index, strict=True):
        equip(rb, weight[li], np.zeros((rb.m, 2)), None)
        rb.evidence.bundle_budget = budget
    team = LocalTeam(len(fpc), edges, options)
    logs = team.run(lambda tr: run_consistency_locally(robots[tr.robot_id], tr,
                                                       resolution="evidence"))
    deleted = np.zeros(len(links), dtype=bool)
    for rb, li in zip(robots, link_index, strict=True):
        if team.network.alive(rb.id):
            deleted[li[~rb.link_alive]] = True
    return deleted, logs, robots, link_index


@settings(max_examples=25, deadline=None)
@given(instances(), st.sampled_from([None, 1, 3]))
def test_local_termination_gives_the_drivers_links_with_the_evidence_rule(inst, budget):
    from pipeline.matching.link_evidence import ratio_llr

    fpc, edges, links = inst
    edges = comm_edges_for(fpc, links, edges)
    weight = ratio_llr(1.0 - links.quality)
    # small budgets: the sets beyond them merged by sync alone, as in the simulator's stage
    ref = resolve_conflicts(fpc, edges, links, resolution="evidence", link_weight=weight,
                            bundle_budget=budget)
    deleted, logs, robots, link_index = _run_team_evidence(fpc, edges, links, weight,
                                                           budget=budget)
    assert np.array_equal(deleted, ref.deleted)
    # both ends cut alike, with the evidence rule's case
    ends = np.zeros(len(links), dtype=int)
    for rb, li in zip(robots, link_index, strict=True):
        np.add.at(ends, li[~rb.link_alive], 1)
        assert set(rb.deleted_case[~rb.link_alive].tolist()) <= {5}
    assert set(ends.tolist()) <= {0, 2}
    # one pass, as in the simulator (a robot cut off from the sets' part of the team sees none)
    assert max(lg.iterations for lg in logs) == ref.stats["iterations"]


def test_evidence_rule_alone_with_a_crash_ends_conflict_free():
    from pipeline.matching.link_evidence import ratio_llr

    fpc, edges, links = random_instance(np.random.default_rng(5), 6, 5, 1.0, 0.9)
    edges = comm_edges_for(fpc, links, edges)
    weight = ratio_llr(1.0 - links.quality)
    # robot 2 crashes in the first evidence pass (detection takes a few rounds before it)
    for crash in (4, 14, 20):
        deleted, logs, _, _ = _run_team_evidence(
            fpc, edges, links, weight,
            NetworkOptions(crash_at={2: crash}, seed=1))
        alive = np.array([i != 2 for i in range(len(fpc))])
        kept = links.subset(~deleted & alive[links.cam_i] & alive[links.cam_j])
        assert is_conflict_free(fpc, kept), crash
        assert logs[2] is None


def test_a_phase_all_robots_start_done_ends_at_round_n_minus_1():
    """Every robot done from the phase start (t0 = 0, the round of ``start``): each ends the
    phase at t0 + n - 1 = n - 1, not a round later."""
    n = 4
    nbrs = {0: [1], 1: [0, 2], 2: [1, 3], 3: [2]}
    waves = {i: TerminationWave(n) for i in range(n)}
    for i in range(n):
        waves[i].start(True, 0)
    ended = {}
    for t in range(1, 10):
        states = {i: waves[i].state() for i in range(n)}
        for i in range(n):
            if waves[i].update(True, 0, {k: states[k] for k in nbrs[i]}):
                ended.setdefault(i, t)
    assert ended == dict.fromkeys(range(n), n - 1)
