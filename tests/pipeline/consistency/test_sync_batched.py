"""The batched ``sync`` engine (pipeline.consistency.engines.sync_batched) against robot-by-robot
stepping (pipeline.consistency.sync.run_sync): the same per-robot final state, rounds,
messages and bytes per kind, and peak memory per robot, on random instances with planted
conflicts."""

from unittest.mock import patch

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from sync_instances import comm_edges, irregular_instance, planted_instance
from test_sync import _reference

from pipeline.consistency.engines import sync_batched
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.engines.sync_batched import (
    run_sync,
    run_sync_batched,
    sync_batched_applies,
)
from pipeline.consistency.sync import FLOODS, equip_sync
from pipeline.transport.simulated import Network, NetworkOptions

SETTINGS = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])

SYNC_ARRAYS = ("label", "other", "open", "tree", "w", "has_best", "best_w", "best_lo",
               "best_hi", "relabeled")
ROBOT_ARRAYS = ("link_alive", "deleted_round", "deleted_case", "deleted_iteration",
                "component")


def _team(fpc, links, weight, flood, options=None, edges=None):
    robots, index = build_robots(fpc, links)
    for rb, li in zip(robots, index, strict=True):
        equip_sync(rb, weight[li], flood)
    edges = comm_edges(links) if edges is None else edges
    return robots, Network(len(fpc), edges, options)


def _both(fpc, links, weight, flood, options=None, batched_only=True, edges=None):
    """Robot by robot and batched on two copies of one team: (result, rounds seen, network,
    robots) of each."""
    out = []
    for run in (run_sync, run_sync_batched):
        robots, net = _team(fpc, links, weight, flood, options, edges)
        seen: list[int] = []
        if run is run_sync_batched and batched_only:
            assert sync_batched_applies(robots, net)
            with patch.object(sync_batched, "run_sync", side_effect=AssertionError("fell back")):
                res = run(robots, net, on_round=seen.append)
        else:
            res = run(robots, net, on_round=seen.append)
        out.append((res, seen, net, robots))
    return out


def _assert_same(a, b) -> None:
    (res_a, seen_a, net_a, robots_a), (res_b, seen_b, net_b, robots_b) = a, b
    assert res_a == res_b
    assert seen_a == seen_b
    assert net_a.counters() == net_b.counters()
    for ra, rb in zip(robots_a, robots_b, strict=True):
        for k in SYNC_ARRAYS:
            np.testing.assert_array_equal(getattr(ra.sync, k), getattr(rb.sync, k),
                                          err_msg=f"robot {ra.id} {k}")
        assert sorted(ra.sync.cams) == sorted(rb.sync.cams), f"robot {ra.id} camera sets"
        for g, row in ra.sync.cams.items():
            np.testing.assert_array_equal(row, rb.sync.cams[g])
        assert ra.sync.rounds == rb.sync.rounds
        for k in ROBOT_ARRAYS:
            np.testing.assert_array_equal(getattr(ra, k), getattr(rb, k),
                                          err_msg=f"robot {ra.id} {k}")
        assert ra.peak_memory_bytes == rb.peak_memory_bytes, f"robot {ra.id} memory"
        # the network holds each robot's peak (the stage's max_robot_memory_bytes)
        assert net_a.peak_memory(ra.id) == ra.peak_memory_bytes, f"robot {ra.id} noted"
        assert ra.peak_memory_bytes > 0 or ra.m == 0, f"robot {ra.id} measured"
        assert net_b.peak_memory(rb.id) == rb.peak_memory_bytes, f"robot {rb.id} noted"


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 9), m=st.integers(2, 6),
       p_link=st.sampled_from([0.5, 0.9, 1.0]), p_swap=st.sampled_from([0.3, 0.6, 0.9]),
       ties=st.booleans(), flood=st.sampled_from(FLOODS),
       graph=st.sampled_from(["complete", "ring2"]))
def test_batched_equals_robot_by_robot(seed, n, m, p_link, p_swap, ties, flood, graph):
    fpc, links, weight = planted_instance(seed, n, m, p_link, p_swap, ties, graph)
    a, b = _both(fpc, links, weight, flood)
    event(f"{a[0]['boruvka_rounds']} Borůvka rounds" if a[0]["boruvka_rounds"] < 3
          else "3 or more Borůvka rounds")
    _assert_same(a, b)


def test_small_pieces_and_a_compacted_camera_store_change_nothing():
    fpc, links, weight = planted_instance(11, 12, 8, 0.9, 0.6, False, "ring2")
    with patch.object(sync_batched, "CHUNK", 5):
        a, b = _both(fpc, links, weight, "links")
    _assert_same(a, b)
    assert a[0]["boruvka_rounds"] >= 3


def test_a_team_without_links():
    fpc = np.array([3, 2, 4])
    links = planted_instance(0, 3, 2, 0.0, 0.0, False)[1]
    robots, _ = _team(fpc, links, np.zeros(0), "links")
    net = Network(3, np.array([[0, 1], [1, 2]]))
    res = run_sync_batched(robots, net)
    assert res == dict(rounds=0, boruvka_rounds=0, support_rounds=0)
    assert net.counters()["messages"] == 0
    assert all((rb.component == -1).all() for rb in robots)


def test_where_it_does_not_apply_the_robots_run_one_by_one():
    fpc, links, weight = planted_instance(5, 5, 4, 1.0, 0.9, False)
    delayed = NetworkOptions(delay_rounds=1)
    robots, net = _team(fpc, links, weight, "links", delayed)
    assert not sync_batched_applies(robots, net)
    a, b = _both(fpc, links, weight, "links", delayed, batched_only=False)
    _assert_same(a, b)
    robots, net = _team(fpc, links, weight, "tree")
    equip_sync(robots[0], robots[0].sync.weight, "links")  # one robot floods otherwise
    assert not sync_batched_applies(robots, net)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 8), m=st.integers(2, 5),
       share=st.sampled_from([0.3, 1.0]), flood=st.sampled_from(FLOODS),
       graph=st.sampled_from(["complete", "ring2"]))
def test_batched_equals_robot_by_robot_with_links_of_evidence_minus_infinity(
        seed, n, m, share, flood, graph):
    # -inf evidence (Links.quality -inf, or a link_weight of -inf) ties with the "no best
    # held" entry of a feature in phase A
    fpc, links, weight = planted_instance(seed, n, m, 0.9, 0.8, True, graph)
    rng = np.random.default_rng(seed)
    weight[rng.random(weight.size) < share] = -np.inf
    _assert_same(*_both(fpc, links, weight, flood))


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7), max_m=st.integers(0, 4),
       p_pair=st.sampled_from([0.3, 0.7, 1.0]), p_link=st.sampled_from([0.5, 1.0]),
       weights=st.sampled_from(["ties", "equal", "normal", "inf"]),
       flood=st.sampled_from(FLOODS), complete=st.booleans())
def test_batched_equals_robot_by_robot_on_irregular_teams(seed, n, max_m, p_pair, p_link,
                                                          weights, flood, complete):
    # one camera, cameras without features or links, several components, comm edges that
    # hold no link, every link of equal evidence, +-inf evidence; and the greedy merge's
    # clusters (test_sync's reference)
    fpc, links, weight = irregular_instance(seed, n, max_m, p_pair, p_link, weights)
    edges = np.array([(i, j) for i in range(n) for j in range(i + 1, n)],
                     dtype=np.int64).reshape(-1, 2) if complete else None
    a, b = _both(fpc, links, weight, flood, edges=edges)
    _assert_same(a, b)
    labels = np.concatenate([rb.sync.label for rb in a[3]])
    clusters = sorted({frozenset(np.flatnonzero(labels == g).tolist())
                       for g in np.unique(labels)}, key=min)
    assert clusters == _reference(fpc, links, weight)


def test_a_link_cut_at_both_ends_after_the_robots_were_equipped_runs_them_one_by_one():
    """The batched evaluation takes the robots' links as ``equip_sync`` left them open; a
    link cut since (at both ends: the tables stay symmetric) leaves them not fresh."""
    fpc, links, weight = planted_instance(5, 5, 4, 1.0, 0.9, False)
    results = []
    for run in (run_sync, run_sync_batched):
        robots, net = _team(fpc, links, weight, "links")
        assert sync_batched_applies(robots, net)
        a = robots[0]
        k, r, s = int(a.link_nbr[0]), int(a.link_r[0]), int(a.link_s[0])
        twin = int(robots[k].find_links(np.array([0]), np.array([r]))[0])
        assert int(robots[k].link_r[twin]) == s
        a.link_alive[0] = robots[k].link_alive[twin] = False
        assert not sync_batched_applies(robots, net)
        results.append((run(robots, net), [], net, robots))
    _assert_same(*results)
