"""The ``sync`` rule (pipeline.consistency.sync): the robots' Borůvka rounds reach exactly the
clusters of the sequential constrained greedy merge, computed here independently (brute-force
triangle counts, a plain list-based merge), and the result is cycle-consistent."""

from itertools import combinations

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st
from sync_instances import comm_edges, planted_instance

from pipeline.consistency.cycles import SUPPORT_VIEWS
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.engines.sync_batched import run_sync
from pipeline.consistency.evidence import TRIANGLE_WEIGHT
from pipeline.consistency.keys import tie_key
from pipeline.consistency.sync import CASE_SYNC, FLOODS, equip_sync
from pipeline.transport.simulated import Network
from pipeline.types import Links


def _instance(seed: int, n: int, m: int, p_link: float, p_swap: float, ties: bool):
    return planted_instance(seed, n, m, p_link, p_swap, ties)


def _reference(fpc, links: Links, weight) -> list[set]:
    """Clusters of the sequential greedy merge, written plainly: triangle support by brute
    force, links sorted by (weight desc, tie key, smaller end, larger end), lists of sets."""
    a, b, cam, w = _reference_weights(fpc, links, weight)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    tie = tie_key(lo, hi).tolist()
    order = sorted(range(len(a)), key=lambda k: (-w[k], tie[k], lo[k], hi[k]))
    cluster = {g: {g} for g in range(int(np.sum(fpc)))}
    for k in order:
        x, y = cluster[a[k]], cluster[b[k]]
        if x is y or {cam[g] for g in x} & {cam[g] for g in y}:
            continue
        merged = x | y
        for g in merged:
            cluster[g] = merged
    return sorted({frozenset(c) for c in cluster.values()}, key=min)


def _reference_weights(fpc, links: Links, weight):
    """Link ends, camera of every feature and each link's weight: local evidence plus one
    per triangle (the agreement rate over ``K`` views beyond ``K`` shared third cameras),
    plus one where no triangle but a quadrangle closes (brute force)."""
    off = np.concatenate([[0], np.cumsum(fpc)])
    a = (off[links.cam_i] + links.feat_i).tolist()
    b = (off[links.cam_j] + links.feat_j).tolist()
    cam = {g: c for c in range(len(fpc)) for g in range(off[c], off[c + 1])}
    nbrs = {g: set() for g in range(off[-1])}
    for x, y in zip(a, b, strict=True):
        nbrs[x].add(y)
        nbrs[y].add(x)
    tau = [len({cam[t] for t in nbrs[x] & nbrs[y]}) for x, y in zip(a, b, strict=True)]
    # a link without triangle counts one when a cycle through four cameras closes over it
    quad = [tau[k] == 0 and any(u in nbrs[y] and len({cam[x], cam[t], cam[u], cam[y]}) == 4
                                for t in nbrs[x] - {y} for u in nbrs[t])
            for k, (x, y) in enumerate(zip(a, b, strict=True))]
    # third cameras both ends are linked into; beyond K of them triangles count as a rate
    shared = [len({cam[t] for t in nbrs[x]} & {cam[t] for t in nbrs[y]})
              for x, y in zip(a, b, strict=True)]
    return a, b, cam, [float(weight[k]) + TRIANGLE_WEIGHT * (
        tau[k] * min(1.0, SUPPORT_VIEWS / max(shared[k], 1)) + quad[k]) for k in range(len(a))]


def _run(fpc, links, weight, flood="links"):
    robots, index = build_robots(fpc, links)
    off = np.concatenate([[0], np.cumsum(fpc)])
    for rb, li in zip(robots, index, strict=True):
        equip_sync(rb, weight[li], flood)
    net = Network(len(fpc), comm_edges(links))
    stats = run_sync(robots, net)
    labels = np.concatenate([rb.sync.label for rb in robots])
    kept = np.zeros(len(links), dtype=bool)
    for rb, li in zip(robots, index, strict=True):
        kept[li] = rb.link_alive
        assert set(np.unique(rb.deleted_case[~rb.link_alive]).tolist()) <= {CASE_SYNC}
    clusters = sorted({frozenset(np.flatnonzero(labels == g).tolist()) for g in
                       np.unique(labels)}, key=min)
    return clusters, labels, kept, stats, off, net


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 6), m=st.integers(2, 5),
       p_link=st.sampled_from([0.5, 0.9, 1.0]), p_swap=st.sampled_from([0.6, 0.9]),
       ties=st.booleans(), flood=st.sampled_from(FLOODS))
def test_robots_reach_the_greedy_merge(seed, n, m, p_link, p_swap, ties, flood):
    fpc, links, weight = _instance(seed, n, m, p_link, p_swap, ties)
    clusters, labels, kept, _, off, _ = _run(fpc, links, weight, flood)
    event("a conflictive input" if _has_conflict(fpc, links) else "a conflict-free input")
    assert clusters == _reference(fpc, links, weight)
    # kept iff both ends in one cluster; no cluster holds two features of one camera
    a = off[links.cam_i] + links.feat_i
    b = off[links.cam_j] + links.feat_j
    np.testing.assert_array_equal(kept, labels[a] == labels[b])
    cam = np.repeat(np.arange(len(fpc)), fpc)
    for c in clusters:
        assert len({int(cam[g]) for g in c}) == len(c)


def _has_conflict(fpc, links) -> bool:
    from pipeline.consistency.centralized import is_conflict_free

    return not is_conflict_free(fpc, links)


def test_generator_plants_conflicts_in_most_examples():
    hits = sum(_has_conflict(*_instance(s, 4, 4, 0.9, 0.8, False)[:2]) for s in range(50))
    assert hits >= 30


def test_a_swapped_pair_is_undone_and_the_rest_kept():
    # 4 cameras x 2 landmarks, all pairs matched; (0, 1) swaps both matches (weak ratio)
    ci, fi, cj, fj, w = [], [], [], [], []
    for i, j in combinations(range(4), 2):
        for k in range(2):
            t = 1 - k if (i, j) == (0, 1) else k
            ci.append(i), fi.append(k), cj.append(j), fj.append(t)
            w.append(-1.0 if (i, j) == (0, 1) else 1.0)
    fpc = np.full(4, 2)
    links = Links(ci, fi, cj, fj)
    clusters, _, kept, stats, _, net = _run(fpc, links, np.array(w))
    assert clusters == [frozenset({0, 2, 4, 6}), frozenset({1, 3, 5, 7})]
    assert kept.tolist() == [(i, j) != (0, 1) for i, j in zip(ci, cj, strict=True)]
    assert stats["boruvka_rounds"] >= 1
    assert net.counters()["messages"] > 0


def test_cluster_labels_are_the_smallest_id_of_each_cluster():
    fpc, links, weight = _instance(3, 5, 4, 1.0, 0.8, False)
    clusters, labels, _, _, _, _ = _run(fpc, links, weight)
    for c in clusters:
        assert {int(labels[g]) for g in c} == {min(c)}


def _alone(fpc, links, weight, options=None):
    """Every robot in its own thread runs the rule alone (reliable channel, termination wave)."""
    from pipeline.consistency.protocols import ProtocolOptions
    from pipeline.consistency.sync_alone import run_sync_locally
    from pipeline.transport.local import LocalTeam

    robots, index = build_robots(fpc, links)
    for rb, li in zip(robots, index, strict=True):
        equip_sync(rb, weight[li])
    edges = np.array(sorted({(int(i), int(j)) for i, j in
                             zip(links.cam_i, links.cam_j, strict=True)}),
                     dtype=np.int64).reshape(-1, 2)
    team = LocalTeam(len(fpc), edges, options)
    proto = ProtocolOptions(reliable=True)
    runs = team.run(lambda end: run_sync_locally(robots[end.robot_id], end, proto, len(fpc)))
    kept = np.zeros(len(links), dtype=bool)
    for rb, li in zip(robots, index, strict=True):
        kept[li] = rb.link_alive
    return kept, runs


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), drop=st.sampled_from([0.0, 0.3]))
def test_a_robot_alone_ends_with_the_simulators_association(seed, drop):
    from pipeline.transport.simulated import NetworkOptions

    fpc, links, weight = _instance(seed, 4, 3, 0.9, 0.8, False)
    _, _, kept_sim, stats, _, _ = _run(fpc, links, weight)
    kept, runs = _alone(fpc, links, weight, NetworkOptions(drop_probability=drop, seed=seed % 1000))
    np.testing.assert_array_equal(kept, kept_sim)
    # every robot took the same Borůvka rounds and phases (the wave ends them together)
    assert {r.iterations for r in runs} == {stats["boruvka_rounds"]}
    assert len({len(r.phases) for r in runs}) == 1


def test_both_flood_graphs_reach_the_same_clusters_with_their_own_costs():
    fpc, links, weight = _instance(7, 6, 5, 1.0, 0.9, False)
    a, _, kept_a, stats_a, _, net_a = _run(fpc, links, weight, "links")
    b, _, kept_b, stats_b, _, net_b = _run(fpc, links, weight, "tree")
    assert a == b
    np.testing.assert_array_equal(kept_a, kept_b)
    assert stats_a["boruvka_rounds"] == stats_b["boruvka_rounds"]
    assert stats_a["rounds"] < stats_b["rounds"]  # here: all links inside are shallower
    with pytest.raises(ValueError, match="flood"):
        equip_sync(build_robots(fpc, links)[0][0], weight[:0], "star")


@pytest.mark.parametrize("engine", ["batched", "per-robot"])
def test_a_cut_link_is_logged_in_iteration_one(engine):
    # ConsistencyResult.iteration is 1-based for a cut link, -1 for a kept one (the merge
    # logged its cuts in iteration 0)
    from pipeline.consistency import resolve_conflicts

    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])  # paper Fig. 1
    res = resolve_conflicts([2, 1, 1, 1], [[0, 1], [1, 2], [2, 3], [0, 3]], links,
                            resolution="sync", engine=engine)
    assert res.deleted.sum() == 1
    assert res.iteration[res.deleted].tolist() == [1]
    assert (res.iteration[~res.deleted] == -1).all()


@pytest.mark.parametrize("engine", ["batched", "per-robot"])
def test_links_of_evidence_minus_infinity_never_merge_twice_in_a_round(engine):
    # cameras 0-1-2 merge first; then the cluster's two -inf links lead to features 25 and
    # 26 of camera 3. Their tie keys are above the one of "no best held" (ids -1, -1): a
    # member without an open link (camera 1) once kept "none" against both, each end took
    # its own link as the cluster's best, and both merged, joining two features of camera 3
    from pipeline.consistency import resolve_conflicts
    from pipeline.consistency.centralized import is_conflict_free

    fpc = np.array([1, 1, 1, 27])
    links = Links([0, 1, 0, 2], [0, 0, 0, 0], [1, 2, 3, 3], [0, 0, 25, 26])
    weight = np.array([1.0, 1.0, -np.inf, -np.inf])
    res = resolve_conflicts(fpc, None, links, resolution="sync", link_weight=weight,
                            engine=engine)
    assert is_conflict_free(fpc, links.subset(~res.deleted))
    clusters = _reference(fpc, links, weight)
    off = np.concatenate([[0], np.cumsum(fpc)])
    a, b = off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j
    together = [any(int(x) in c and int(y) in c for c in clusters) for x, y in zip(a, b, strict=True)]
    assert (~res.deleted).tolist() == together == [True, True, True, False]


def test_a_quadrangle_makes_sync_decide_otherwise_than_the_evidence_rule():
    # README, "sync": without poses it is the evidence rule's greedy merge except for the
    # quadrangles. a = 0:0 links to b = 1:0 (evidence 0, no triangle, but the 4-cycle
    # a - 2:0 - 3:0 - b closes over it) and to p = 4:0 (evidence 1), which holds b2 = 1:1
    # (evidence 5). sync weighs a - b 0 + TRIANGLE_WEIGHT > 1 and cuts a - p; the evidence
    # rule weighs it 0 and cuts a - b (and one link of the cycle)
    from pipeline.consistency import resolve_conflicts

    links = Links([0, 0, 2, 1, 0, 1], [0, 0, 0, 0, 0, 1], [1, 2, 3, 3, 4, 4], [0, 0, 0, 0, 0, 0])
    weight = np.array([0.0, -5.0, -5.0, -5.0, 1.0, 5.0])
    fpc = [1, 2, 1, 1, 1]
    cut = {rule: resolve_conflicts(fpc, None, links, resolution=rule,
                                   link_weight=weight).deleted for rule in ("sync", "evidence")}
    assert np.flatnonzero(cut["sync"]).tolist() == [4]
    assert cut["evidence"][0] and not cut["evidence"][4]
