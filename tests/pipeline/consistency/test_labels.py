"""Detection by label flooding (pipeline.consistency.labels): the outcome the rows of Sec. III
give — conflictive features, set labels, roots (eq. 10), track names — and so the same cuts
of Alg. 1, with memory and bytes that follow the links."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sync_instances import comm_edges, planted_instance

from pipeline.consistency import resolve_conflicts
from pipeline.consistency.engines.driver import build_robots, detect_once
from pipeline.consistency.engines.paper_labels import run_labels
from pipeline.transport.simulated import Network
from pipeline.types import Links

instances = st.tuples(st.integers(0, 2**32 - 1), st.integers(3, 7), st.integers(2, 6),
                      st.sampled_from([0.5, 0.9, 1.0]), st.sampled_from([0.3, 0.9]),
                      st.sampled_from(["complete", "ring2"]))


def _instance(args):
    seed, n, m, p_link, p_swap, graph = args
    fpc, links, _ = planted_instance(seed, n, m, p_link, p_swap, False, graph)
    return fpc, links


@settings(max_examples=60, deadline=None)
@given(args=instances)
def test_flooded_labels_give_the_rows_outcome(args):
    fpc, links = _instance(args)
    rows = detect_once(fpc, links, engine="per-robot").robots
    robots, _ = build_robots(fpc, links)
    out = run_labels(robots, Network(len(fpc), comm_edges(links)), 1)
    for a, b in zip(rows, robots, strict=True):
        np.testing.assert_array_equal(a.conflictive, b.conflictive)
        np.testing.assert_array_equal(a.set_label, b.set_label)
        np.testing.assert_array_equal(a.track_label, b.track_label)
        assert a.root_of_set == b.root_of_set
    assert out["conflictive_features"] == sum(int(rb.conflictive.sum()) for rb in rows)


@settings(max_examples=40, deadline=None)
@given(args=instances)
def test_the_rule_cuts_what_the_paper_rule_cuts(args):
    fpc, links = _instance(args)
    edges = comm_edges(links)
    paper = resolve_conflicts(fpc, edges, links, resolution="paper", engine="per-robot")
    flood = resolve_conflicts(fpc, edges, links, resolution="paper-labels")
    np.testing.assert_array_equal(paper.deleted, flood.deleted)
    np.testing.assert_array_equal(paper.case, flood.case)
    np.testing.assert_array_equal(paper.iteration, flood.iteration)
    np.testing.assert_array_equal(paper.round, flood.round)
    assert flood.stats["resolution"] == "paper-labels"


def test_memory_and_bytes_follow_the_links():
    # 8 cameras, 12 landmarks each, every pair matched with swaps: one set per landmark
    # pair joined by the swaps, rows of up to 96 features
    fpc, links, _ = planted_instance(3, 8, 12, 1.0, 0.9, False)
    edges = comm_edges(links)
    paper = resolve_conflicts(fpc, edges, links, resolution="paper")
    flood = resolve_conflicts(fpc, edges, links, resolution="paper-labels")
    np.testing.assert_array_equal(paper.deleted, flood.deleted)
    assert paper.deleted.any()
    assert flood.stats["max_robot_memory_bytes"] * 3 < paper.stats["max_robot_memory_bytes"]
    assert flood.stats["bytes"] * 3 < paper.stats["bytes"]


def test_memory_is_reported_without_any_conflict():
    """A conflict-free input runs the detection only: the robots' memory is still reported
    (it read 0 bytes per robot when no resolution phase followed)."""
    links = Links(np.array([0, 1]), np.array([0, 0]), np.array([1, 2]), np.array([0, 0]))
    res = resolve_conflicts([1, 1, 1], comm_edges(links), links, resolution="paper-labels")
    assert not res.deleted.any() and res.stats["max_robot_memory_bytes"] > 0


def _alone(fpc, links, options=None):
    """Every robot in its own thread runs the rule alone (reliable channel, termination wave)."""
    from pipeline.consistency.alone import run_paper_labels_locally
    from pipeline.consistency.protocols import ProtocolOptions
    from pipeline.transport.local import LocalTeam

    robots, index = build_robots(fpc, links)
    team = LocalTeam(len(fpc), comm_edges(links), options)
    proto = ProtocolOptions(reliable=True)
    runs = team.run(lambda end: run_paper_labels_locally(robots[end.robot_id], end, proto,
                                                         len(fpc)))
    kept = np.zeros(len(links), dtype=bool)
    for rb, li in zip(robots, index, strict=True):
        kept[li] = rb.link_alive
    return kept, runs, team


@settings(max_examples=10, deadline=None)
@given(args=instances)
def test_a_robot_alone_cuts_what_the_simulator_cuts(args):
    fpc, links = _instance(args)
    sim = resolve_conflicts(fpc, comm_edges(links), links, resolution="paper-labels")
    kept, runs, _ = _alone(fpc, links)
    np.testing.assert_array_equal(kept, ~sim.deleted)
    assert len({r.iterations for r in runs}) == 1


@pytest.mark.parametrize("p", [0.2, 0.5])
def test_a_robot_alone_under_loss_ends_conflict_free(p):
    # Alg. 1's cuts depend on which request arrives first: under loss they may differ from
    # the simulator's, but the association ends conflict-free and no robot is written off
    from pipeline.consistency.centralized import is_conflict_free
    from pipeline.transport.simulated import NetworkOptions

    fpc, links, _ = planted_instance(11, 5, 4, 0.9, 0.9, False)
    kept, runs, team = _alone(fpc, links, NetworkOptions(drop_probability=p, seed=2))
    assert team.network.dropped > 0
    assert not kept.all()
    assert is_conflict_free(fpc, links.subset(kept))
    assert not any(r.lost_neighbours for r in runs)


@pytest.mark.parametrize("n", [5, 50])
def test_a_long_cycle_ends_within_the_flooding_bound(n):
    """A cycle through n + 1 cameras back to a second feature of camera 0: the labels settle
    in diam rounds and the dup flag they reveal floods back another diam, past the m_sum + 2
    rounds the simulator allowed (it stopped with 'label flooding did not end')."""
    ci, cj = np.arange(n + 1), np.r_[np.arange(1, n + 1), 0]
    fi, fj = np.zeros(n + 1, np.int64), np.r_[np.zeros(n, np.int64), 1]
    lo = ci < cj
    links = Links(np.where(lo, ci, cj), np.where(lo, fi, fj), np.where(lo, cj, ci),
                  np.where(lo, fj, fi))
    fpc = np.r_[2, np.ones(n, np.int64)]
    edges = comm_edges(links)
    paper = resolve_conflicts(fpc, edges, links, resolution="paper")
    flood = resolve_conflicts(fpc, edges, links, resolution="paper-labels")
    assert int(flood.deleted.sum()) == 1
    np.testing.assert_array_equal(paper.deleted, flood.deleted)
