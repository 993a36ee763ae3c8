"""Hungarian matching of landmark descriptors: χ² and L2 distances, the ratio gate, links."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.matching.landmarks import (
    chi2_distance,
    guided_match,
    hungarian_match,
    l2_distance,
    match_landmark_edges,
)


def test_chi2_by_hand():
    a = np.array([[1.0, 1.0, 0.0]])        # normalised (0.5, 0.5, 0)
    b = np.array([[0.0, 2.0, 2.0]])        # normalised (0, 0.5, 0.5)
    # ½ [(0.5)²/0.5 + 0 + (0.5)²/0.5] = 0.5
    assert chi2_distance(a, b)[0, 0] == pytest.approx(0.5)
    assert chi2_distance(a, a)[0, 0] == 0.0
    assert chi2_distance(np.zeros((1, 3)), np.zeros((1, 3)))[0, 0] == 0.0


def test_l2_by_hand():
    assert l2_distance(np.array([[0.0, 0.0]]), np.array([[3.0, 4.0]]))[0, 0] == pytest.approx(5.0)


def test_ratio_gate_drops_ambiguous_assignment():
    cost = np.array([[0.10, 0.90, 0.95],
                     [0.80, 0.50, 0.55],   # 0.50 vs alternative 0.55: ratio 0.91
                     [0.90, 0.85, 0.20]])
    pairs, dist, rho = hungarian_match(cost, ratio=None)
    assert pairs.tolist() == [[0, 0], [1, 1], [2, 2]]
    assert rho[1] == pytest.approx(0.5 / 0.55)
    kept, _, _ = hungarian_match(cost, ratio=0.8)
    assert kept.tolist() == [[0, 0], [2, 2]]


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 7), st.integers(1, 7), st.integers(0, 10_000))
def test_assignment_is_one_to_one(k_i, k_j, seed):
    cost = np.random.default_rng(seed).random((k_i, k_j))
    pairs, _, _ = hungarian_match(cost, ratio=None)
    assert len(pairs) == min(k_i, k_j)
    assert len(set(pairs[:, 0])) == len(pairs) == len(set(pairs[:, 1]))


def test_edges_recover_a_permutation():
    rng = np.random.default_rng(0)
    base = rng.random((6, 10))
    perm = rng.permutation(6)
    links, _ = match_landmark_edges([base, base[perm]], np.array([[0, 1]]), "histogram", 0.8)
    assert len(links) == 6
    assert (perm[links.feat_j] == links.feat_i).all()
    assert (links.quality == 1.0).all()  # distance 0, so ratio 0


def test_bad_ratio_and_kind():
    d = [np.ones((2, 3)), np.ones((2, 3))]
    with pytest.raises(InputError, match="--ratio 1.5"):
        match_landmark_edges(d, np.array([[0, 1]]), "histogram", 1.5)
    with pytest.raises(InputError, match="descriptor kind"):
        match_landmark_edges(d, np.array([[0, 1]]), "binary", 0.8)


def _two_views(n=20, seed=0):
    """Projections of random 3D points into two cameras (a real epipolar geometry)."""
    rng = np.random.default_rng(seed)
    X = rng.uniform([-1, -1, 4], [1, 1, 8], size=(n, 3))
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    a = 0.2
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    t = np.array([-1.0, 0.1, 0.2])

    def project(P):
        p = P @ K.T
        return p[:, :2] / p[:, 2:]

    return project(X), project(X @ R.T + t)


def test_guided_matching_undoes_a_descriptor_swap():
    x_i, x_j = _two_views()
    cost = np.ones((20, 20))
    cost[np.arange(20), np.arange(20)] = 0.1
    far = int(np.argmax(np.abs(x_i[:, 1] - x_i[0, 1])))  # far from landmark 0's epipolar line
    cost[0, 0] = cost[far, far] = 0.5
    cost[0, far] = cost[far, 0] = 0.05  # the descriptors prefer the swap
    plain, _, _ = hungarian_match(cost, ratio=None)
    assert {(0, far), (far, 0)} <= set(map(tuple, plain.tolist()))
    pairs, found = guided_match(cost, x_i, x_j, 1.0)
    assert found
    assert sorted(map(tuple, pairs.tolist())) == [(k, k) for k in range(20)]


def test_guided_matching_without_enough_pairs_keeps_the_assignment():
    x_i, x_j = _two_views(n=5)
    pairs, found = guided_match(np.eye(5)[::-1], x_i, x_j)
    assert not found and len(pairs) == 5


def test_epipolar_needs_keypoints():
    d = [np.ones((2, 3)), np.ones((2, 3))]
    with pytest.raises(InputError, match="needs the keypoints"):
        match_landmark_edges(d, np.array([[0, 1]]), "histogram", None, None, "epipolar")
