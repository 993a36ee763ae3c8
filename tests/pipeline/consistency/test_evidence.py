"""The evidence-aware resolution: its guarantees (hypothesis) against a reference that does
not use its code (every subset of a set's links tried; triangles counted by hand), and
hand-solved cases."""

import math

import numpy as np
import pytest
from consistency_graphs import instances, random_instance
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components, shortest_path

from pipeline.association import AssociationGraph
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import is_conflict_free, union_find_conflicts
from pipeline.consistency.evidence import evidence_cut, triangle_support
from pipeline.errors import InputError
from pipeline.types import Links

#: the triangle weight the rule documents: a good link's point is matched in a third camera
#: about half the time, the two ends of a spurious link rarely (about 1 in 20): log(0.5 / 0.05)
LOG_TEN = math.log(10.0)
#: largest conflictive set (in links) the exhaustive reference solves: 2**14 subsets
EXHAUSTIVE_LINKS = 14
ENGINES = ("batched", "per-robot")


def conflictive_set_diameter(fpc, links) -> int:
    """Largest diameter of a conflictive set of the input (0 without one)."""
    A = AssociationGraph(fpc, links).adjacency()
    if A.nnz == 0:
        return 0
    D = shortest_path(A, unweighted=True, directed=False)
    _, conflictive = union_find_conflicts(fpc, links)
    sub = D[np.ix_(conflictive, conflictive)]
    return int(sub[np.isfinite(sub)].max(initial=0))


def components(gid_a, gid_b, n_features) -> np.ndarray:
    """Connected component (its smallest feature) of every feature, by repeated relaxation."""
    label = np.arange(n_features)
    while True:
        low = np.minimum(label[gid_a], label[gid_b])
        new = label.copy()
        np.minimum.at(new, gid_a, low)
        np.minimum.at(new, gid_b, low)
        new = new[new]
        if (new == label).all():
            return label
        label = new


def triangles_by_hand(a, b, cam) -> np.ndarray:
    """Third cameras in which both ends of each link match one common feature."""
    nbrs: dict = {}
    for x, y in zip(a.tolist(), b.tolist(), strict=True):
        nbrs.setdefault(x, set()).add(y)
        nbrs.setdefault(y, set()).add(x)
    return np.array([len({cam[z] for z in nbrs[x] & nbrs[y]})
                     for x, y in zip(a.tolist(), b.tolist(), strict=True)])


def exhaustive_kept(a, b, cam, weight) -> np.ndarray:
    """The links the rule keeps in one conflictive set, found among all ``2**E`` subsets.

    The rule merges by decreasing weight (ties: smaller ``(min gid, max gid)`` first) and
    never merges two clusters that share a camera. The subsets whose clusters hold each
    camera at most once are closed under removal, so that greedy merge keeps, of all of
    them, the subset that comes first in lexicographic order of the links sorted that way:
    the subset searched for here. (It is not the minimum-weight cut:
    ``test_the_rule_is_greedy_not_the_minimum_weight_cut``.)
    """
    E = a.size
    rank = np.lexsort((np.maximum(a, b), np.minimum(a, b), -weight))
    nodes, inv = np.unique(np.r_[a, b], return_inverse=True)
    ia, ib = inv[:E][rank], inv[E:][rank]
    subsets = np.arange(2 ** E)
    on = (subsets[:, None] >> (E - 1 - np.arange(E))) & 1 == 1  # the first link: highest bit
    label = np.tile(np.arange(nodes.size), (subsets.size, 1))
    for _ in range(nodes.size):
        for k in range(E):
            low = np.minimum(label[on[:, k], ia[k]], label[on[:, k], ib[k]])
            label[on[:, k], ia[k]] = low
            label[on[:, k], ib[k]] = low
    node_cam = np.array([cam[g] for g in nodes.tolist()])
    u, v = np.nonzero(np.triu(node_cam[:, None] == node_cam[None, :], k=1))
    conflict_free = (label[:, u] != label[:, v]).all(axis=1)
    kept = np.zeros(E, dtype=bool)
    kept[rank] = on[subsets[conflict_free].max()]
    return kept


def expected_cut(fpc, links, link_weight):
    """What the rule must cut, solved centrally without its code, in every conflictive set of
    at most :data:`EXHAUSTIVE_LINKS` links.

    Returns ``(deleted, solved, n_solved)``: the cut of the exhaustive reference, (L,) bool;
    the links of the sets it solved, (L,) bool; how many sets it solved.
    """
    off = np.concatenate([[0], np.cumsum(fpc)])
    cam = np.repeat(np.arange(len(fpc)), fpc)
    a, b = off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j
    label = components(a, b, int(off[-1]))
    deleted = np.zeros(len(links), dtype=bool)
    solved = np.zeros(len(links), dtype=bool)
    for lab in np.unique(label[a]):
        sel = np.flatnonzero(label[a] == lab)
        feats = np.unique(np.r_[a[sel], b[sel]])
        if np.unique(cam[feats]).size == feats.size or sel.size > EXHAUSTIVE_LINKS:
            continue  # not conflictive (nothing to cut), or too large to try every subset
        w = link_weight[sel] + LOG_TEN * triangles_by_hand(a[sel], b[sel], cam)
        deleted[sel] = ~exhaustive_kept(a[sel], b[sel], cam, w)
        solved[sel] = True
    return deleted, solved, int(np.unique(label[a[solved]]).size)


def clusters(fpc, links, deleted):
    """Global feature ids of both ends of each link, and the kept cluster of every feature."""
    off = np.concatenate([[0], np.cumsum(fpc)])
    a, b = off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j
    return a, b, components(a[~deleted], b[~deleted], int(off[-1]))


def cut_links_join_one_camera_twice(fpc, links, deleted) -> bool:
    """Every cut link joins two kept clusters that share a camera (none could be kept)."""
    cam = np.repeat(np.arange(len(fpc)), fpc)
    a, b, label = clusters(fpc, links, deleted)
    cams_of: dict = {}
    for g, lab in enumerate(label.tolist()):
        cams_of.setdefault(lab, set()).add(int(cam[g]))
    return all(cams_of[label[x]] & cams_of[label[y]]
               for x, y in zip(a[deleted].tolist(), b[deleted].tolist(), strict=True))


def posed_sets(fpc, links, projections) -> np.ndarray:
    """(L,) bool: the links of the conflictive sets in which every camera's pose is known."""
    if projections is None:
        return np.zeros(len(links), dtype=bool)
    cam = np.repeat(np.arange(len(fpc)), fpc)
    a, b, label = clusters(fpc, links, np.zeros(len(links), dtype=bool))
    unknown = {label[g] for g in np.r_[a, b].tolist() if projections[cam[g]] is None}
    seen, conflictive = set(), set()
    for g in np.unique(np.r_[a, b]).tolist():
        if (label[g], cam[g]) in seen:
            conflictive.add(label[g])
        seen.add((label[g], cam[g]))
    return np.array([label[x] in conflictive - unknown for x in a.tolist()], dtype=bool)


def kept_tracks_triangulate(fpc, links, deleted, keypoints, projections, tol_px=2.0) -> bool:
    """Every kept cluster is one point: the least-squares solution of its rays
    (``x × P X = 0``, all rows at once) lies in front of each camera and reprojects within
    ``tol_px`` of each observation."""
    cam = np.repeat(np.arange(len(fpc)), fpc)
    off = np.concatenate([[0], np.cumsum(fpc)])
    a, _, label = clusters(fpc, links, deleted)
    for lab in np.unique(label[a[~deleted]]).tolist():
        members = np.flatnonzero(label == lab)
        P = np.stack([projections[cam[g]] for g in members])                  # (k, 3, 4)
        xy = np.stack([keypoints[cam[g]][g - off[cam[g]]] for g in members]).astype(np.float64)
        rows = np.concatenate([xy[:, :1] * P[:, 2] - P[:, 0], xy[:, 1:] * P[:, 2] - P[:, 1]])
        X = np.linalg.svd(rows)[2][-1]
        p = P @ (X / X[3])                                                    # (k, 3)
        if (p[:, 2] <= 0).any() or (np.hypot(*(p[:, :2] / p[:, 2:] - xy).T) > tol_px).any():
            return False
    return True


def check_evidence(fpc, edges, links, keypoints=None, projections=None, link_weight=None):
    """Every guarantee of the evidence rule on one instance, on both engines.

    In a set without the geometric test (no pose given, or one of its robots' unknown) the
    cut is the exhaustive reference's (sets of at most :data:`EXHAUSTIVE_LINKS` links), and
    no cut link could have been kept; in a set with it, every kept cluster triangulates.
    ``link_weight``: the links' local evidence (default: three times their quality).

    Returns ``(result, n_solved)``: the batched engine's result and the number of sets
    checked against the exhaustive reference.
    """
    weight = links.quality * 3.0 if link_weight is None else np.asarray(link_weight)
    results = [resolve_conflicts(fpc, edges, links, resolution="evidence", link_weight=weight,
                                 keypoints=keypoints, projections=projections, engine=engine)
               for engine in ENGINES]
    res = results[0]
    for other in results[1:]:
        np.testing.assert_array_equal(other.deleted, res.deleted)
    assert res.stats["resolution"] == "evidence"
    # conflict-free at the end, after one pass
    assert is_conflict_free(fpc, res.kept())
    _, conflictive = union_find_conflicts(fpc, links)
    off = np.concatenate([[0], np.cumsum(fpc)])
    in_sets = conflictive[off[links.cam_i] + links.feat_i]
    assert res.stats["iterations"] == (1 if in_sets.any() else 0)
    # nothing cut outside a conflictive set; symmetric deletions; reasons and cases
    assert not (res.deleted & ~in_sets).any()
    assert res.stats["asymmetric_links"] == 0
    assert set(res.case[res.deleted].tolist()) <= {"evidence"}
    assert (res.reason[res.deleted] == "resolution").all()
    # each set cut as the rule promises, solved without its code
    posed = posed_sets(fpc, links, projections)
    plain = links.subset(~posed)
    deleted, solved, n_solved = expected_cut(fpc, plain, weight[~posed])
    np.testing.assert_array_equal(res.deleted[~posed][solved], deleted[solved])
    assert cut_links_join_one_camera_twice(fpc, plain, res.deleted[~posed])
    if posed.any():
        assert kept_tracks_triangulate(fpc, links.subset(posed), res.deleted[posed], keypoints,
                                       projections)
    # the stated round bound: flooding within diam(C), plus one round of redundant copies
    for it in res.stats["per_iteration"]:
        if it["conflictive_sets"]:
            assert it["resolution_rounds"] <= conflictive_set_diameter(fpc, links) + 1
    return res, n_solved


def check_many(strategy, examples: int, p_unknown: float | None = None) -> tuple[int, int]:
    """:func:`check_evidence` on ``examples`` drawn instances, with random cameras
    (:func:`_random_cameras`) unless ``p_unknown`` is None; returns the number of instances
    and of the sets solved exhaustively."""
    count = [0, 0]

    @settings(max_examples=examples, deadline=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(strategy, st.integers(0, 2**32 - 1))
    def run(inst, seed):
        fpc, edges, links = inst
        cameras = () if p_unknown is None else _random_cameras(fpc, seed, p_unknown)
        _, n_solved = check_evidence(fpc, edges, links, *cameras)
        event(f"sets solved exhaustively: {min(n_solved, 3)}{'+' if n_solved >= 3 else ''}")
        count[0] += 1
        count[1] += n_solved

    run()
    return count[0], count[1]


def test_evidence_properties():
    drawn, solved = check_many(instances(), 150)
    assert solved >= drawn // 2  # the exhaustive reference checked sets, not only the rest


def test_evidence_properties_larger():
    check_many(instances(max_n=10, max_feat=12), 30)


def _random_cameras(fpc, seed, p_unknown=0.0):
    """Random keypoints per camera and a projection matrix near ``[I | (0, 0, 5)]`` for each,
    ``None`` (pose unknown) with probability ``p_unknown``."""
    rng = np.random.default_rng(seed)
    keypoints = [rng.uniform(0, 100, size=(m, 2)).astype(np.float32) for m in fpc]
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    projections = [None if p_unknown and rng.random() < p_unknown else
                   K @ np.c_[np.eye(3), rng.normal(0, 0.1, 3) + [0, 0, 5]] for _ in fpc]
    return keypoints, projections


def test_evidence_properties_with_the_geometric_test():
    check_many(instances(max_n=6, max_feat=5), 40, p_unknown=0.0)


def test_evidence_with_some_poses_unknown_solves_each_set_as_its_robots_hold_it():
    # a set with a robot of unknown pose skips the geometric test (the exhaustive reference
    # holds there); a set whose robots all know theirs keeps it, even when its bundles share
    # messages with the other set's
    drawn, solved = check_many(instances(max_n=7, max_feat=5), 40, p_unknown=0.3)
    assert solved >= drawn // 4


def test_a_bundle_keeps_its_projection_in_a_message_shared_with_a_set_of_unknown_pose():
    # set A on the robot cycle 0-1-2-4 (camera 0 twice), every pose known; set B on 0-1-3
    # (camera 0 twice), robot 3's pose unknown. Robot 1 forwards robot 2's A bundle and
    # robot 3's B bundle to robot 0 in one message, the first copy robot 0 receives of the A
    # bundle: it must arrive with its projection, or robot 0 solves A without the geometric
    # test while robots 2 and 4 use it (links cut at one end only)
    links = Links([0, 1, 2, 0, 0, 1, 0], [0, 0, 0, 1, 2, 1, 3], [1, 2, 4, 4, 1, 3, 3],
                  [0, 0, 0, 0, 1, 0, 0], np.full(7, 0.5))
    fpc = np.array([4, 2, 1, 1, 1])
    rng = np.random.default_rng(0)
    keypoints = [rng.uniform(0, 100, size=(m, 2)).astype(np.float32) for m in fpc]
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    projections = [None if c == 3 else K @ np.c_[np.eye(3), [0.1 * c, 0, 5]] for c in range(5)]
    res, solved = check_evidence(fpc, None, links, keypoints, projections)
    assert res.deleted[:4].all()  # the random keypoints of A never triangulate: all of A cut
    assert solved == 1  # B, without the geometric test
    # B: links 4-6 join global features 2-5, 5-7 and 3-7 (0:2 - 1:1 - 3:0 - 0:3), of equal
    # weight: merged in the order (2, 5), (3, 7), then (5, 7) would hold camera 0 twice
    assert res.deleted[4:].tolist() == [False, True, False]


def test_evidence_on_larger_random_graph():
    rng = np.random.default_rng(7)
    fpc, edges, links = random_instance(rng, n=15, max_feat=30, p_edge=0.3, p_link=0.7)
    res, _ = check_evidence(fpc, edges, links)
    assert 0 < res.deleted.sum() < len(links)
    assert res.stats["max_robot_memory_bytes"] > 0
    assert res.stats["messages_by_kind"]["bundle"] > 0


def test_a_triangle_outweighs_a_stronger_link():
    # cameras 0..3; the chain 0:0 - 1:0 - 2:0 - 0:1 joins two features of camera 0, and
    # 3:0 matches both 0:0 and 1:0 (a triangle). By local evidence alone 0:0-1:0 (2.0) is the
    # weakest link of the chain; its triangle adds log 10 = 2.30 (4.30), so the chain is cut
    # at 2:0-0:1 (2.5) instead. 0:0-3:0 and 1:0-3:0 (0.1 each, +2.30 from the triangle) join
    # 3:0 to the cluster of 0:0 and 1:0.
    links = Links([0, 1, 0, 0, 1], [0, 0, 1, 0, 0], [1, 2, 2, 3, 3], [0, 0, 0, 0, 0])
    weight = np.array([2.0, 3.0, 2.5, 0.1, 0.1])
    for engine in ENGINES:
        res = resolve_conflicts([2, 1, 1, 1], None, links, resolution="evidence",
                                link_weight=weight, engine=engine)
        assert res.deleted.tolist() == [False, False, True, False, False], engine
    # without the triangle, 0:0-1:0 would go first, then 1:0-3:0 (3:0 then sits with 0:0)
    cams = [0, 1, 2, 0, 3]  # features 0:0, 1:0, 2:0, 0:1, 3:0 as 0..4
    assert (~exhaustive_kept(np.array([0, 1, 3, 0, 1]), np.array([1, 2, 2, 4, 4]), cams,
                             weight)).tolist() == [True, False, False, False, True]


def test_the_rule_is_greedy_not_the_minimum_weight_cut():
    # 2:0 - 3:0 (5.0) is merged first; then 2:0 - 0:0 and 2:0 - 1:0 join, and 3:0 - 0:1 and
    # 3:0 - 1:1 (3.0 each) would put cameras 0 and 1 twice in that cluster: both cut (6.0 of
    # evidence), where cutting 2:0 - 3:0 alone (5.0) would leave two conflict-free tracks.
    links = Links([0, 1, 2, 0, 1], [0, 0, 0, 1, 1], [2, 2, 3, 3, 3], [0, 0, 0, 0, 0])
    weight = np.array([3.0, 3.0, 5.0, 3.0, 3.0])
    res, solved = check_evidence([2, 2, 1, 1], None, links, link_weight=weight)
    assert solved == 1
    assert res.deleted.tolist() == [False, False, False, True, True]


def test_fig1_cuts_the_weakest_link():
    # paper Fig. 1: f^0_0 - f^3_1, f^0_0 - f^1_0, f^1_0 - f^2_0, f^2_0 - f^3_0: camera 3 twice
    for weak in range(4):
        q = np.full(4, 0.8)
        q[weak] = 0.2
        links = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0], q)
        res = resolve_conflicts([1, 1, 1, 2], None, links, resolution="evidence")
        assert res.deleted.tolist() == [k == weak for k in range(4)]


def test_evidence_cut_by_hand():
    # a 4-cycle a0-b0-c0-a1 (camera a twice) plus a strong triangle b0-c0-d0
    a = np.array([0, 1, 2, 3, 1, 2])
    b = np.array([1, 2, 3, 0, 4, 4])
    cam = {0: 0, 1: 1, 2: 2, 3: 0, 4: 3}
    ca = np.array([cam[x] for x in a])
    cb = np.array([cam[x] for x in b])
    w = np.array([3.0, 5.0, 1.0, 2.0, 4.0, 4.0])
    # order 1-2 (5), 1-4, 2-4 (4, inside), 0-1 (3), 3-0 (2: camera 0 twice → cut), 2-3 (1: cut)
    assert evidence_cut(a, b, ca, cb, w).tolist() == [False, False, True, True, False, False]
    # a cut link whose ends end in one cluster anyway is kept: never cut inside a cluster
    assert not evidence_cut([0, 1, 0], [1, 2, 2], [0, 1, 0], [1, 2, 2], [3.0, 2.0, 1.0]).any()


def test_evidence_cut_geometric_test_rejects_inconsistent_merge():
    # three cameras looking at two points: the link from camera 2 to the wrong point is
    # epipolar-consistent with camera 0 only by chance; its track does not triangulate
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    P = [K @ np.c_[np.eye(3), [-x, 0, 0]] for x in (0.0, 1.0, 2.0)]
    X1, X2 = np.array([0.5, 0.2, 10.0, 1.0]), np.array([0.5, 0.9, 12.0, 1.0])

    def proj(Pk, X):
        p = Pk @ X
        return p[:2] / p[2]

    # features: 0 = X1 in cam 0, 1 = X1 in cam 1, 2 = X2 in cam 2
    kp = {0: proj(P[0], X1), 1: proj(P[1], X1), 2: proj(P[2], X2)}
    Pg = {0: P[0], 1: P[1], 2: P[2]}
    cut = evidence_cut([0, 1], [1, 2], [0, 1], [1, 2], [2.0, 1.0], kp, Pg)
    assert cut.tolist() == [False, True]
    kp[2] = proj(P[2], X1)  # the right observation merges
    assert not evidence_cut([0, 1], [1, 2], [0, 1], [1, 2], [2.0, 1.0], kp, Pg).any()


def test_triangle_support_counts_third_cameras():
    # link 0-1 has common neighbours 2 (camera 2) and 3 (camera 2) and 4 (camera 3)
    cams = np.array([0, 1, 2, 2, 3])
    a = np.array([0, 0, 1, 0, 1, 0, 1])
    b = np.array([1, 2, 2, 3, 3, 4, 4])
    assert triangle_support(a, b, lambda g: cams[g]).tolist() == [2, 1, 1, 1, 1, 1, 1]


def test_unknown_resolution_is_an_input_error():
    links = Links([0], [0], [1], [0])
    with pytest.raises(InputError, match="resolution 'best'"):
        resolve_conflicts([1, 1], None, links, resolution="best")


def test_faulty_network_falls_back_to_reliable_alg1():
    from pipeline.transport.simulated import NetworkOptions

    rng = np.random.default_rng(3)
    fpc, edges, links = random_instance(rng, n=6, max_feat=5, p_edge=0.8, p_link=0.9)
    res = resolve_conflicts(fpc, edges, links, NetworkOptions(drop_probability=0.1, seed=1),
                            resolution="evidence")
    assert res.stats["resolution"] == "paper" and res.stats["protocol"] == "reliable"
    assert is_conflict_free(fpc, res.kept())


def test_components_of_result_hold_each_camera_once():
    rng = np.random.default_rng(11)
    fpc, edges, links = random_instance(rng, n=8, max_feat=8, p_edge=0.6, p_link=0.9)
    res, _ = check_evidence(fpc, edges, links)
    _, lab = connected_components(AssociationGraph(fpc, res.kept()).adjacency(), directed=False)
    cam = np.repeat(np.arange(len(fpc)), fpc)
    assert np.unique(np.stack([lab, cam], 1), axis=0).shape[0] == lab.size
