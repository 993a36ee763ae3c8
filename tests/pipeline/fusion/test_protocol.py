"""The fusion stage's rounds: message sizes, the distributed stop rule, lockstep under faults."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import shortest_path

from pipeline.fusion.landmarks import fuse_tracks
from pipeline.fusion.protocol import LinkTraffic, message_bytes, stop_counters
from pipeline.transport import HEADER_BYTES
from pipeline.transport.simulated import Network, NetworkOptions
from tests.pipeline.test_faults import _planted_rig


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 8), seed=st.integers(0, 10_000), rounds=st.integers(1, 14))
def test_stop_counter_means_every_robot_in_reach_was_flagged_in_one_round(n, seed, rounds):
    """c_i(t) >= m  =>  every node at distance r <= m - 1 was flagged in rounds t-m+1 .. t-r."""
    rng = np.random.default_rng(seed)
    # a random connected graph: a random tree plus random extra edges
    edges = {(int(rng.integers(0, k)), k) for k in range(1, n)}
    edges |= {tuple(sorted(map(int, rng.choice(n, 2, replace=False))))
              for _ in range(int(rng.integers(0, n)))} if n > 2 else set()
    e = np.array(sorted(edges), dtype=np.int64).reshape(-1, 2)
    adj = np.zeros((n, n))
    adj[e[:, 0], e[:, 1]] = adj[e[:, 1], e[:, 0]] = 1
    dist = shortest_path(adj, unweighted=True)
    flags = rng.random((rounds, n)) < 0.8
    counter = np.zeros(n, dtype=np.int64)
    for t in range(rounds):
        counter = stop_counters(counter, flags[t], e, np.zeros(n, dtype=bool))
        for i in range(n):
            m = int(counter[i])
            for j in range(n):
                r = int(dist[i, j])
                if r <= m - 1:
                    assert flags[t - m + 1:t - r + 1, j].all()


def test_message_bytes_header_counters_bitmap_and_changed_tracks():
    size = message_bytes([0, 1, 9], [0, 1, 2], changed_bytes=161, counter_bytes=1)
    assert size.tolist() == [0, HEADER_BYTES + 1 + 1 + 161, HEADER_BYTES + 9 + 2 + 2 * 161]


def test_link_traffic_bundles_only_the_tracks_a_link_carries():
    # robots 0-1-2 on a path; track 0 seen by 0 and 1, track 1 by all three
    n = 3
    node_edges = np.array([[0, 1], [n + 0, n + 1], [n + 1, n + 2]])
    traffic = LinkTraffic(node_edges, np.array([0, 0, 1]), np.array([[0, 1], [1, 2]]))
    running = np.ones(2 * n, dtype=bool)
    changed = np.zeros(2 * n, dtype=bool)
    changed[n + 1] = True
    run, chg = traffic.directed(running, changed, np.ones(3, dtype=bool))
    assert run.tolist() == [2, 2, 1, 1]        # link 0-1 carries 2 tracks, link 1-2 one
    assert chg.tolist() == [0, 1, 1, 0]        # robot 1's bundle of track 1 changed


def test_stop_rule_keeps_the_cuts_and_the_float64_wire_is_the_fixed_round_scheme():
    views, feats, links, edges = _planted_rig()
    fixed = fuse_tracks(views, feats, links, edges, sigma_px=0.5, stop=False)
    for mode in ("exact", "metropolis"):
        stopped = fuse_tracks(views, feats, links, edges, sigma_px=0.5, consensus=mode)
        np.testing.assert_array_equal(stopped.cut_links, fixed.cut_links)
        assert stopped.stats["settled"] and stopped.stats["rounds"] < fixed.stats["rounds"]
        assert stopped.stats["bytes"] < fixed.stats["bytes"] / 10
    # the exact mode on a complete graph of 4: entries in round 1, the last flags in round 2
    exact = fuse_tracks(views, feats, links, edges, sigma_px=0.5)
    assert exact.stats["rounds"] == 2 and exact.stats["maxc_rounds"] == 0
    np.testing.assert_allclose(exact.points, fixed.points, atol=1e-6)
    # a float64 wire runs the very arithmetic of the fixed-round scheme
    f64 = fuse_tracks(views, feats, links, edges, sigma_px=0.5, wire="float64", rounds=30,
                      consensus="metropolis")
    ref = fuse_tracks(views, feats, links, edges, sigma_px=0.5, stop=False, rounds=30)
    np.testing.assert_array_equal(f64.points, ref.points)
    np.testing.assert_array_equal(f64.cut_links, ref.cut_links)


def test_fusion_under_message_loss_ends_with_the_fault_free_result():
    views, feats, links, edges = _planted_rig()
    clean = fuse_tracks(views, feats, links, edges, sigma_px=0.5)
    net = Network(len(views), edges, NetworkOptions(drop_probability=0.3, seed=4))
    lossy = fuse_tracks(views, feats, links, edges, sigma_px=0.5, transport=net)
    np.testing.assert_array_equal(lossy.cut_links, clean.cut_links)
    np.testing.assert_array_equal(lossy.points, clean.points)
    st_ = lossy.stats
    assert st_["settled"] and st_["rounds"] == clean.stats["rounds"]
    assert st_["network_rounds"] > st_["rounds"] and st_["dropped"] > 0
    assert st_["retransmissions"] > 0 and st_["crashed"] == []
    assert net.counters()["bytes_by_kind"]["fusion"] > 0


@pytest.mark.parametrize("consensus", ["exact", "metropolis"])
@pytest.mark.parametrize("options", [dict(drop_probability=0.3, seed=4), dict(delay_rounds=2)])
def test_fusion_traffic_by_kind_adds_up_on_a_faulty_network(consensus, options):
    """The stage's figures by message kind are what the network carried: they add up to its
    messages and bytes, setup included (every robot tells each neighbour its pose first)."""
    views, feats, links, edges = _planted_rig()
    clean = fuse_tracks(views, feats, links, edges, sigma_px=0.5, consensus=consensus).stats
    net = Network(len(views), edges, NetworkOptions(**options))
    st_ = fuse_tracks(views, feats, links, edges, sigma_px=0.5, transport=net,
                      consensus=consensus).stats
    by_kind = st_["bytes_by_kind"]
    assert sum(by_kind.values()) == st_["bytes"] == net.counters()["bytes"] > 0
    assert by_kind["fusion-setup"] == st_["setup_bytes"] >= clean["setup_bytes"] > 0
    assert st_["setup_messages"] >= clean["setup_messages"] == 2 * len(edges)
    assert by_kind["fusion"] > 0


@pytest.mark.parametrize("mode,crash_round", [("exact", 1), ("exact", 2), ("metropolis", 4)])
def test_robot_crashed_during_fusion_leaves_the_graph_and_is_not_judged(mode, crash_round):
    views, feats, links, edges = _planted_rig()
    net = Network(len(views), edges, NetworkOptions(crash_at={2: crash_round}))
    res = fuse_tracks(views, feats, links, edges, sigma_px=0.5, transport=net, consensus=mode)
    touches_2 = (links.cam_i == 2) | (links.cam_j == 2)
    assert res.stats["crashed"] == [2]
    assert set(res.stats["robots_lost"]) == {"0", "1", "3"}
    assert not res.cut_links[touches_2].any()
    assert not (~res.obs_inlier[res.obs_cam == 2]).any()


def test_robot_crashed_during_consistency_takes_no_part_in_fusion():
    from pipeline.faults import FaultConfig
    from pipeline.stages import clean_association

    views, feats, links, edges = _planted_rig()
    cleaning = clean_association(views, feats, edges, links, resolution="paper",
                                 faults=FaultConfig(crash=((2, 0),)))
    fs = cleaning.fusion_stats
    assert fs["enabled"] and fs["crashed_before_fusion"] == [2]
    led = cleaning.ledger
    touches_2 = (led.links.cam_i == 2) | (led.links.cam_j == 2)
    assert not (led.reason[touches_2] == "fusion-outlier").any()
    # the planted wrong keypoint was robot 2's: with robot 2 gone nothing else is cut
    assert not (led.reason == "fusion-outlier").any()


@pytest.mark.parametrize("drop", [0.0, 0.3])
def test_fusion_under_delay_ends_with_the_fault_free_result_and_more_network_rounds(drop):
    views, feats, links, edges = _planted_rig()
    clean = fuse_tracks(views, feats, links, edges, sigma_px=0.5)
    rounds = {}
    for delay in (0, 3):
        net = Network(len(views), edges, NetworkOptions(drop_probability=drop, delay_rounds=delay,
                                                        seed=4))
        if not drop and not delay:
            continue
        late = fuse_tracks(views, feats, links, edges, sigma_px=0.5, transport=net)
        np.testing.assert_array_equal(late.cut_links, clean.cut_links)
        np.testing.assert_array_equal(late.points, clean.points)
        st_ = late.stats
        # the timers are set for the delay: a late message is never taken for a lost robot
        assert st_["settled"] and st_["rounds"] == clean.stats["rounds"]
        assert st_["crashed"] == [] and st_["robots_lost"] == {}
        rounds[delay] = st_["network_rounds"]
    # every logical round waits D rounds more for each message
    assert rounds[3] >= 4 * clean.stats["rounds"]
    if drop:
        assert rounds[3] > rounds[0]


def test_fusion_transport_carries_the_delay_and_its_timers():
    from pipeline.faults import FaultConfig
    from pipeline.fusion.protocol import LockstepExchange

    edges = np.array([[0, 1], [1, 2], [2, 3]])
    net = FaultConfig(delay_rounds=5).fusion_transport(edges, np.array([0, 1, 3]), 10)
    assert net.options.delay_rounds == 5
    ex = LockstepExchange(net, np.array([[0, 1]]))
    assert ex.options.retransmit_after == 12 and ex.options.loss_timeout == 60


@settings(max_examples=15, deadline=None)
@given(robot=st.integers(0, 3), when=st.integers(0, 14), drop=st.sampled_from([0.0, 0.3]),
       seed=st.integers(0, 50))
def test_a_crash_anywhere_in_consistency_or_fusion_never_cuts_the_crashed_robots_links_by_fusion(
        robot, when, drop, seed):
    """Through both stages: a robot crashed in either is no fusion voter and fusion never cuts
    its links; every cut link keeps one reason; fusion ends settled."""
    from pipeline.faults import FaultConfig
    from pipeline.stages import clean_association

    views, feats, links, edges = _planted_rig()
    faults = FaultConfig(crash=((robot, when),), drop_prob=drop, seed=seed)
    cleaning = clean_association(views, feats, edges, links, resolution="paper", faults=faults)
    fs, f = cleaning.fusion_stats, cleaning.faults
    led = cleaning.ledger
    assert len(led.links) == len(links)
    assert ((led.status == "deleted") == (led.reason != "")).all()
    hit = [int(k) for k in f["crashed"]] + fs["crashed"]
    assert len(hit) <= 1 and fs["settled"]
    assert sorted(hit + [int(k) for k in f["crashes_not_reached"]]) == [robot]
    if hit:
        touches = (led.links.cam_i == robot) | (led.links.cam_j == robot)
        assert not (led.reason[touches] == "fusion-outlier").any()
    if fs["crashed"]:
        assert f["crashed_during_fusion"] == {str(robot): when}
