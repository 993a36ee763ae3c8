"""Hungarian matching of landmark descriptors: χ² and L2 distances, the ratio gate, links."""

import numpy as np
import pytest
from epipolar_views import project_two
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


def test_chi2_memory_stays_bounded_and_values_match_the_formula():
    """χ² of 400 x 400 histograms of 60 bins: the distances of all pairs were computed in
    one go through (400, 400, 60) temporaries (77 MB each; 7.8 GB of peak memory for 2000
    landmarks, a labelled folder run-landmarks accepts); now a block of rows at a time, with
    the same values."""
    import tracemalloc

    rng = np.random.default_rng(0)
    a, b = rng.uniform(0, 1, (400, 60)), rng.uniform(0, 1, (400, 60))
    a[3] = 0.0  # an empty histogram: 0 / 0 bins count 0
    tracemalloc.start()
    try:
        got = chi2_distance(a, b)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6  # 317 MB before
    an, bn = a / np.maximum(a.sum(1, keepdims=True), 1e-300), b / b.sum(1, keepdims=True)
    for r in (0, 3, 200, 399):
        s, d = an[r] + bn, (an[r] - bn) ** 2
        want = 0.5 * np.where(s > 0, d / np.where(s > 0, s, 1.0), 0.0).sum(axis=1)
        np.testing.assert_allclose(got[r], want, rtol=1e-12, atol=1e-15)


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
    return project_two(rng.uniform([-1, -1, 4], [1, 1, 8], size=(n, 3)), 0.2)


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


def test_guided_matching_memory_stays_bounded_and_blocks_change_nothing(monkeypatch):
    """The epipolar band of 1200 x 1200 landmarks: its Sampson errors were computed on every
    pair at once (230 MB of traced temporaries here; 4.3 GB peak for two images of 5000
    landmarks, a folder run-landmarks accepts); now a block of rows at a time, and the pairs
    do not depend on the block size."""
    import tracemalloc

    import pipeline.matching.landmarks as lm

    x_i, x_j = _two_views(n=1200, seed=1)
    cost = np.random.default_rng(2).uniform(0, 1, (1200, 1200))
    cost[np.arange(1200), np.arange(1200)] = 0.0
    tracemalloc.start()
    try:
        pairs, found = guided_match(cost, x_i, x_j, 1.0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert found and peak < 130e6
    assert sorted(map(tuple, pairs.tolist())) == [(k, k) for k in range(1200)]
    small = cost[:60, :60].copy()
    small[0, 0], small[0, 7], small[7, 0] = 0.5, 0.05, 0.05  # a swap the band undoes
    whole = guided_match(small, x_i[:60], x_j[:60], 1.0)[0]
    monkeypatch.setattr(lm, "_PAIRS_BLOCK", 7)
    np.testing.assert_array_equal(guided_match(small, x_i[:60], x_j[:60], 1.0)[0], whole)


def test_guided_matching_without_enough_pairs_keeps_the_assignment():
    x_i, x_j = _two_views(n=5)
    pairs, found = guided_match(np.eye(5)[::-1], x_i, x_j)
    assert not found and len(pairs) == 5


def test_epipolar_needs_keypoints():
    d = [np.ones((2, 3)), np.ones((2, 3))]
    with pytest.raises(InputError, match="needs the keypoints"):
        match_landmark_edges(d, np.array([[0, 1]]), "histogram", None, None, "epipolar")


def test_guided_matching_does_not_depend_on_landmark_or_image_order():
    """RANSAC samples by index: fed the pairs in label order, the epipolar model (and so the
    pairs kept) changed with the order of the landmarks in the label files and with which of
    the two images came first by name."""
    n = 40
    x_i, x_j = _two_views(n=n, seed=0)
    rng = np.random.default_rng(0)
    x_i, x_j = x_i + rng.normal(0, 1.5, x_i.shape), x_j + rng.normal(0, 1.5, x_j.shape)
    cost = rng.uniform(0.3, 1, (n, n))
    cost[np.arange(n), np.arange(n)] = rng.uniform(0, 0.6, n)
    pairs = sorted(map(tuple, guided_match(cost, x_i, x_j, 3.0)[0].tolist()))
    p = rng.permutation(n)  # the same landmarks, listed in another order
    permuted = guided_match(cost[np.ix_(p, p)], x_i[p], x_j[p], 3.0)[0]
    assert sorted((int(p[r]), int(p[s])) for r, s in permuted) == pairs
    swapped = guided_match(cost.T, x_j, x_i, 3.0)[0]  # image j first
    assert sorted((s, r) for r, s in swapped.tolist()) == pairs
