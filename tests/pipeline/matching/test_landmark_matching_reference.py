"""Landmark matching against independent computations: scipy's ``cdist`` for the L2 distance,
every permutation for the assignment and its ratio gate, the plain assignment where guided
matching has no model (fewer than 8 pairs, or a planar scene that a homography explains)."""

import itertools

import numpy as np
import pytest
from epipolar_views import project_two
from scipy.spatial.distance import cdist

from pipeline.matching.landmarks import (
    guided_match,
    hungarian_match,
    l2_distance,
    match_landmark_edges,
)


def test_l2_distance_equals_cdist():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(7, 5)), rng.normal(size=(4, 5))
    np.testing.assert_allclose(l2_distance(a, b), cdist(a, b), rtol=1e-12, atol=1e-12)


def brute_force_assignment(cost, ratio):
    """Minimum-cost assignment of the smaller side by enumeration; the gate: cost over the
    nearest other entry of its row or column, kept when ``<= ratio`` (0 / 0 counts 1)."""
    ki, kj = cost.shape
    best, pairs = np.inf, None
    if ki <= kj:
        for cols in itertools.permutations(range(kj), ki):
            c = cost[np.arange(ki), cols].sum()
            if c < best:
                best, pairs = c, list(zip(range(ki), cols, strict=True))
    else:
        for rows in itertools.permutations(range(ki), kj):
            c = cost[rows, np.arange(kj)].sum()
            if c < best:
                best, pairs = c, sorted(zip(rows, range(kj), strict=True))
    out = []
    for r, s in pairs:
        others = [cost[r, k] for k in range(kj) if k != s] + [cost[k, s] for k in range(ki)
                                                               if k != r]
        alt = min(others) if others else np.inf
        rho = cost[r, s] / alt if alt > 0 else (np.inf if cost[r, s] > 0 else 1.0)
        if ratio is None or rho <= ratio:
            out.append((r, s, rho))
    return out


@pytest.mark.parametrize("seed", range(20))
def test_hungarian_match_equals_enumeration(seed):
    rng = np.random.default_rng(seed)
    ki, kj = rng.integers(1, 6, 2)
    cost = rng.uniform(0, 1, (ki, kj))
    for ratio in (None, 0.5, 0.8, 1.0):
        pairs, dist, rho = hungarian_match(cost, ratio)
        want = brute_force_assignment(cost, ratio)
        assert [tuple(p) for p in pairs.tolist()] == [(r, s) for r, s, _ in want]
        np.testing.assert_allclose(dist, [cost[r, s] for r, s, _ in want])
        np.testing.assert_allclose(rho, [x for _, _, x in want])


def test_ratio_gate_keeps_a_pair_exactly_at_the_ratio_and_reads_zero_over_zero_as_one():
    # pair (0, 0) at 0.4 with its nearest alternative 0.5 (in its column): ratio 0.8
    cost = np.array([[0.4, 0.9], [0.5, 0.45]])
    pairs, _, rho = hungarian_match(cost, 0.8)
    assert [0, 0] in pairs.tolist()
    np.testing.assert_allclose(rho[pairs[:, 0] == 0], [0.8])
    # identical descriptors on both sides: 0 / 0, an ambiguous pair (ratio 1), kept at 1 only
    zero = np.zeros((2, 2))
    np.testing.assert_array_equal(hungarian_match(zero, 1.0)[2], [1.0, 1.0])
    assert len(hungarian_match(zero, 0.99)[0]) == 0


def _views(X):
    return project_two(X, 0.25)


@pytest.mark.parametrize("n", [5, 7])
def test_without_enough_pairs_the_epipolar_geometry_gates_like_the_descriptors(n):
    # fewer than 8 pairs: no model, the assignment and the ratio gate of geometry "none"
    rng = np.random.default_rng(n)
    X = rng.uniform([-1, -1, 4], [1, 1, 8], size=(n, 3))
    kp = list(_views(X))
    desc = [rng.normal(size=(n, 6)), rng.normal(size=(n, 6))]
    plain, _ = match_landmark_edges(desc, np.array([[0, 1]]), "vector", 0.9)
    guided, stats = match_landmark_edges(desc, np.array([[0, 1]]), "vector", 0.9, kp,
                                         "epipolar")
    assert stats["edges_without_model"] == 1
    assert 0 < len(plain) < n  # the gate dropped some pairs
    for f in ("cam_i", "feat_i", "cam_j", "feat_j", "quality"):
        np.testing.assert_array_equal(getattr(guided, f), getattr(plain, f))


def test_a_planar_scene_keeps_the_assignment():
    # every landmark on one plane: a homography explains the pairs, F is degenerate
    rng = np.random.default_rng(3)
    X = np.c_[rng.uniform(-1, 1, (30, 2)), np.full(30, 6.0)]
    x_i, x_j = _views(X)
    cost = rng.uniform(0.5, 1.0, (30, 30))
    cost[np.arange(30), np.arange(30)] = 0.1
    pairs, found = guided_match(cost, x_i, x_j, 3.0)
    assert not found
    assert sorted(map(tuple, pairs.tolist())) == [(k, k) for k in range(30)]
