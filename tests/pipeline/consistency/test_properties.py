"""Property tests of the distributed stage against union-find and the paper's bounds."""

import numpy as np
import pytest
import scipy.sparse as sp
from consistency_graphs import instances, random_instance
from hypothesis import HealthCheck, given, settings
from scipy.sparse.csgraph import connected_components, shortest_path

from pipeline.association import AssociationGraph
from pipeline.commgraph import comm_edges_for
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import is_conflict_free, union_find_conflicts
from pipeline.consistency.engines.driver import detect_once
from pipeline.transport.simulated import Network

SETTINGS = settings(max_examples=250, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def diameter(fpc, links) -> int:
    """Longest shortest path in the association graph ``G`` (within components)."""
    A = AssociationGraph(fpc, links).adjacency()
    if A.nnz == 0:
        return 0
    D = shortest_path(A, unweighted=True, directed=False)
    return int(D[np.isfinite(D)].max())


@SETTINGS
@given(instances())
def test_detection_equals_union_find_for_every_robot(inst):
    fpc, edges, links = inst
    once = detect_once(fpc, links, network=Network(len(fpc), edges))
    robots, det = once.robots, once.stats
    labels, conflictive = union_find_conflicts(fpc, links)
    off = np.concatenate([[0], np.cumsum(fpc)])
    for rb in robots:
        gids = off[rb.id] + np.arange(rb.m)
        linked = np.zeros(rb.m, dtype=bool)
        linked[rb.link_r] = True
        for r in np.flatnonzero(linked):
            expect = np.flatnonzero(labels == labels[gids[r]])
            assert np.array_equal(np.sort(rb.X[r].indices), expect)
        np.testing.assert_array_equal(rb.conflictive, conflictive[gids])
        # every conflictive set touching a feature of the robot is known, with its members
        for r in np.flatnonzero(rb.conflictive):
            assert rb.set_label[r] == np.flatnonzero(labels == labels[gids[r]]).min()
            assert rb.set_label[r] in rb.root_of_set
    # Cor. 3.6: every robot stops within d + 1 rounds
    assert det["t_stop"].max() <= diameter(fpc, links) + 1


def _roots_by_eq10(fpc, links):
    labels, conflictive = union_find_conflicts(fpc, links)
    cam = np.repeat(np.arange(len(fpc)), fpc)
    roots = {}
    for lab in np.unique(labels[conflictive]):
        counts = np.bincount(cam[labels == lab], minlength=len(fpc))
        roots[int(np.flatnonzero(labels == lab).min())] = int(np.argmax(counts))  # ties: lowest
    return roots


@SETTINGS
@given(instances())
def test_roots_agree_with_eq10(inst):
    fpc, edges, links = inst
    robots = detect_once(fpc, links, network=Network(len(fpc), edges)).robots
    expected = _roots_by_eq10(fpc, links)
    for rb in robots:
        for label, root in rb.root_of_set.items():
            assert expected[label] == root


@SETTINGS
@given(instances())
def test_resolution_properties(inst):
    check_resolution(*inst)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances(max_n=10, max_feat=12))
def test_resolution_properties_larger(inst):
    check_resolution(*inst)


@pytest.mark.parametrize("n, max_feat, p_edge, p_link, seed",
                         [(8, 10, 0.5, 0.8, 158), (10, 12, 0.4, 0.8, 50), (10, 12, 0.4, 0.8, 97)])
def test_resolution_properties_over_several_iterations(n, max_feat, p_edge, p_link, seed):
    inst = random_instance(np.random.default_rng(seed), n, max_feat, p_edge, p_link)
    res = check_resolution(*inst)
    assert res.stats["iterations"] >= 2  # the loop of Prop. 4.5 is exercised


def check_resolution(fpc, edges, links):
    """All the guarantees of Sec. IV on one instance; returns the result."""
    n = len(fpc)
    res = resolve_conflicts(fpc, edges, links, resolution="paper")
    kept = res.kept()
    off = np.concatenate([[0], np.cumsum(fpc)])
    cam_of = np.repeat(np.arange(n), fpc)

    # Prop. 4.5: zero conflictive sets after the loop
    assert is_conflict_free(fpc, kept)
    # only deletions, symmetric on both ends, and only inside conflictive sets of the input
    assert res.stats["asymmetric_links"] == 0
    _, conflictive = union_find_conflicts(fpc, links)
    assert not (res.deleted & ~conflictive[off[links.cam_i] + links.feat_i]).any()
    assert set(res.case[res.deleted].tolist()) <= {"b", "c"}
    assert (res.round[res.deleted] >= 1).all() and (res.iteration[res.deleted] >= 1).all()
    assert (res.reason[res.deleted] == "resolution").all() and (res.reason[~res.deleted] == "").all()

    # Thm. 4.3: components have >= 2 features, no camera twice, and are components of G'
    _, kept_labels = connected_components(AssociationGraph(fpc, kept).adjacency(), directed=False)
    for q in np.unique(res.component[res.component >= 0]):
        members = np.flatnonzero(res.component == q)
        assert members.size >= 2
        assert np.unique(cam_of[members]).size == members.size
        assert res.component[q] == q  # the root feature opened it
        assert np.unique(kept_labels[members]).size == 1
        assert np.array_equal(np.flatnonzero(kept_labels == kept_labels[members[0]]), members)

    # bounds per iteration: detection <= d + 1 on the graph it ran on, resolution within n
    for it in res.stats["per_iteration"]:
        k = it["iteration"]
        alive = (res.iteration < 0) | (res.iteration >= k)
        assert it["t_stop"].max() <= diameter(fpc, links.subset(alive)) + 1
        if it["conflictive_sets"]:
            assert it["last_assignment_round"] <= n - 1  # Thm. 4.3 (i)
            assert res.round[res.iteration == k].max(initial=0) <= n
            assert it["resolution_rounds"] <= n + 1
    return res


def test_larger_random_graph_matches_union_find_and_ends_conflict_free():
    rng = np.random.default_rng(7)
    fpc, edges, links = random_instance(rng, n=15, max_feat=30, p_edge=0.3, p_link=0.7)
    labels, conflictive = union_find_conflicts(fpc, links)
    assert conflictive.any()  # the instance is a real test
    res = resolve_conflicts(fpc, edges, links, resolution="paper")
    assert is_conflict_free(fpc, res.kept())
    assert res.stats["asymmetric_links"] == 0
    assert 0 < res.deleted.sum() < len(links)
    assert res.stats["max_robot_memory_bytes"] > 0


def test_comm_graph_none_uses_linked_cameras():
    rng = np.random.default_rng(3)
    fpc, edges, links = random_instance(rng, n=6, max_feat=5, p_edge=0.8, p_link=0.9)
    e = comm_edges_for(fpc, links, None)
    assert sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(6, 6)).nnz == len(e)
    a = resolve_conflicts(fpc, None, links, resolution="paper")
    b = resolve_conflicts(fpc, edges, links, resolution="paper")
    np.testing.assert_array_equal(a.deleted, b.deleted)


def test_detection_rounds_follow_the_association_graph_not_the_comm_graph():
    """Cor. 3.6's ``d`` is the diameter of the association graph ``G``: three cameras that all
    talk to each other (comm diameter 1) need 18 rounds on a chain of 17 links (README)."""
    from pipeline.types import Links
    rows = []
    for k in range(6):
        rows += [(0, k, 1, k), (1, k, 2, k)] + ([(0, k + 1, 2, k)] if k < 5 else [])
    ci, fi, cj, fj = (np.array(c) for c in zip(*rows, strict=True))
    links = Links(ci, fi, cj, fj)
    fpc = np.array([6, 6, 6])
    det = detect_once(fpc, links, np.array([[0, 1], [0, 2], [1, 2]]))
    assert diameter(fpc, links) == 17
    assert det.stats["t_stop"].max() == 18
