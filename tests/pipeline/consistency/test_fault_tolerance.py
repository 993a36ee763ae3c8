"""The consistency stage on a faulty network: lossy links, crashed robots, switching topology.

Random association graphs (Assumptions 2.1–2.3) on random comm graphs, under random fault
schedules; after the loop the survivors' links must be conflict-free, only deletions may have
happened (each with a reason) and links to robots that died before the last detection must
be cut with reason ``robot-lost``.
"""


import numpy as np
import pytest
from consistency_graphs import instances, random_instance
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.commgraph import comm_edges_for
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import is_conflict_free, union_find_conflicts
from pipeline.consistency.engines.driver import detect_once
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.transport.simulated import NetworkOptions, recurrent_topology
from pipeline.types import Links

RELIABLE = ProtocolOptions(reliable=True)
FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def detect(fpc, edges, links, options=None, reliable=True):
    """One detection; returns the robots (their ``X``, ``conflictive``, ``t_stop``)."""
    proto = RELIABLE if reliable else ProtocolOptions(reliable=False)
    return detect_once(fpc, links, edges, options, proto, max_rounds=100_000).robots


def exact(fpc, links, robots) -> bool:
    """Every robot's rows and conflictive flags equal union-find (Def. 2.4)."""
    labels, conflictive = union_find_conflicts(fpc, links)
    off = np.concatenate([[0], np.cumsum(fpc)])
    for rb in robots:
        gids = off[rb.id] + np.arange(rb.m)
        for r in np.unique(rb.link_r):
            if not np.array_equal(np.sort(rb.X[r].indices), np.flatnonzero(labels == labels[gids[r]])):
                return False
        if not np.array_equal(rb.conflictive, conflictive[gids]):
            return False
    return True


@FAST
@given(instances())
def test_reliable_protocol_on_a_lossless_network_is_the_paper_protocol(inst):
    fpc, edges, links = inst
    a = resolve_conflicts(fpc, edges, links, resolution="paper")
    b = resolve_conflicts(fpc, edges, links, protocol=RELIABLE, resolution="paper")
    np.testing.assert_array_equal(a.deleted, b.deleted)
    np.testing.assert_array_equal(a.round, b.round)
    np.testing.assert_array_equal(a.case, b.case)
    for pa, pb in zip(a.stats["per_iteration"], b.stats["per_iteration"], strict=True):
        np.testing.assert_array_equal(pa["t_stop"], pb["t_stop"])  # Prop. 3.5 fires alike
    # nothing lost, nothing sent again, nobody suspected; heartbeats may be sent (a robot still
    # detecting tells a linked neighbour it sent nothing to for heartbeat_every rounds that it
    # is alive, lossless network or not: reliable.py, "Crashes and timeouts")
    faults = b.stats["faults"]
    assert faults["retransmissions"] == faults["dropped"] == faults["links_cut_robot_lost"] == 0
    assert faults["robots_lost"] == {}


@FAST
@given(instances(), st.sampled_from([0.1, 0.3, 0.5]), st.integers(0, 2**16))
def test_lockstep_detection_is_exact_under_loss(inst, p, seed):
    fpc, edges, links = inst
    lossless = detect(fpc, edges, links, reliable=False)
    robots = detect(fpc, edges, links, NetworkOptions(drop_probability=p, seed=seed))
    assert exact(fpc, links, robots)
    # the logical stop rounds are those of the lossless run (Cor. 3.6 still holds)
    assert [rb.t_stop for rb in robots] == [rb.t_stop for rb in lossless]


@FAST
@given(instances(), st.integers(0, 2**16))
def test_lockstep_detection_is_exact_on_a_switching_topology(inst, seed):
    fpc, edges, links = inst
    e = comm_edges_for(fpc, links, edges)
    robots = detect(fpc, edges, links, NetworkOptions(topology=recurrent_topology(e, 0.4, 5, seed)))
    assert exact(fpc, links, robots)


def test_paper_rule_alone_stops_early_under_loss():
    """Why the protocol is needed: with the paper's rule only, detection goes wrong under loss."""
    wrong = 0
    for seed in range(20):
        fpc, edges, links = random_instance(np.random.default_rng(seed), 8, 6, 0.6, 0.9)
        robots = detect(fpc, edges, links, NetworkOptions(drop_probability=0.3, seed=seed),
                        reliable=False)
        wrong += not exact(fpc, links, robots)
    assert wrong >= 10


@st.composite
def fault_schedules(draw, n):
    p = draw(st.sampled_from([0.0, 0.0, 0.1, 0.3, 0.5]))
    crashes = draw(st.dictionaries(st.integers(0, n - 1), st.integers(0, 60), max_size=2))
    switching = draw(st.booleans())
    return p, crashes, switching, draw(st.integers(0, 2**16))


def check_survivors(fpc, edges, links, p, crashes, switching, seed):
    e = comm_edges_for(fpc, links, edges)
    topo = recurrent_topology(e, 0.5, 4, seed) if switching else None
    opts = NetworkOptions(drop_probability=p, crash_at=crashes, topology=topo, seed=seed)
    res = resolve_conflicts(fpc, edges, links, opts, protocol=RELIABLE, resolution="paper")
    surv = res.stats["survivors"]
    both = surv[links.cam_i] & surv[links.cam_j]
    # zero conflictive sets among the surviving robots' links (Prop. 4.5 on the survivors)
    assert is_conflict_free(fpc, links.subset(~res.deleted & both))
    # nothing but deletions, each with a reason; symmetric between survivors
    assert set(res.reason[res.deleted].tolist()) <= {"resolution", "robot-lost"}
    assert (res.reason[~res.deleted] == "").all()
    assert res.stats["asymmetric_links"] == 0
    # a robot that died before the last detection began has every link to a survivor cut
    last_start = res.stats["per_iteration"][-1]["start_round"]
    for k, r in res.stats["faults"]["crashed"].items():
        if r < last_start:
            touch = ((links.cam_i == k) | (links.cam_j == k)) & (surv[links.cam_i] | surv[links.cam_j])
            assert res.deleted[touch].all()
            assert set(res.reason[touch].tolist()) <= {"robot-lost", "resolution"}
    return res


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_random_graphs_under_random_fault_schedules(data):
    fpc, edges, links = data.draw(instances(max_n=9, max_feat=8))
    check_survivors(fpc, edges, links, *data.draw(fault_schedules(len(fpc))))


def fig1():
    return [1, 1, 1, 2], Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0])


def test_fig1_robot_d_crashes_survivors_keep_their_chain():
    fpc, links = fig1()
    opts = NetworkOptions(crash_at={3: 2})
    res = resolve_conflicts(fpc, None, links, opts, resolution="paper")
    # A, B, C hold the chain f1^A-f1^B-f1^C, which has no conflict once D is gone
    assert res.deleted.tolist() == [True, False, False, True]
    assert res.reason.tolist() == ["robot-lost", "", "", "robot-lost"]
    assert res.stats["faults"]["crashed"] == {3: 2}
    assert res.stats["faults"]["robots_lost"] == {3: [0, 2]}
    assert res.stats["protocol"] == "reliable"
    # the neighbours waited the stated timeout T, not forever
    T = ProtocolOptions().loss_timeout
    assert T <= res.stats["faults"]["rounds"] <= 4 * T


def test_crash_during_resolution_fig1():
    fpc, links = fig1()
    base = resolve_conflicts(fpc, None, links, protocol=RELIABLE, resolution="paper")
    start = base.stats["per_iteration"][0]["detection_rounds"]
    res = resolve_conflicts(fpc, None, links, NetworkOptions(crash_at={1: start + 1}),
                            resolution="paper")
    assert res.stats["faults"]["crashed"] == {1: start + 1}
    surv = res.stats["survivors"]
    both = surv[links.cam_i] & surv[links.cam_j]
    assert is_conflict_free(fpc, links.subset(~res.deleted & both))
    assert res.deleted[(links.cam_i == 1) | (links.cam_j == 1)].all()


def test_link_down_for_longer_than_the_timeout_is_cut_as_robot_lost():
    fpc, links = fig1()
    edges = np.array([[0, 1], [0, 3], [1, 2], [2, 3]])
    # edge (0, 3) is up in round 0 only; everything else always up
    opts = NetworkOptions(topology=lambda t: edges if t == 0 else edges[[0, 2, 3]])
    res = resolve_conflicts(fpc, edges, links, opts, resolution="paper")
    assert res.reason[0] == "robot-lost"  # link A-f2^D
    assert res.stats["faults"]["robots_lost"] == {0: [3], 3: [0]}
    assert is_conflict_free(fpc, res.kept())


@pytest.mark.parametrize("p", [0.1, 0.3, 0.5])
def test_loss_only_costs_rounds_and_messages_not_links(p):
    fpc, edges, links = random_instance(np.random.default_rng(5), 10, 10, 0.5, 0.8)
    base = resolve_conflicts(fpc, edges, links, resolution="paper")
    res = resolve_conflicts(fpc, edges, links, NetworkOptions(drop_probability=p, seed=1),
                            resolution="paper")
    assert is_conflict_free(fpc, res.kept())
    assert res.stats["faults"]["retransmissions"] > 0
    assert res.stats["detection_rounds"] >= base.stats["detection_rounds"]
    # the first detection (lockstep, exact) finds the same conflictive features
    assert res.stats["per_iteration"][0]["conflictive_features"] == \
        base.stats["per_iteration"][0]["conflictive_features"]
