"""The limits of :func:`pipeline.matching.pairs.match_pair`: ``min_matches`` counts as enough
(``>=``), a ratio of 1 is allowed, and a threshold of ``None`` scales with the larger image."""

import numpy as np
import pytest

import pipeline.matching.pairs as matching
from pipeline.matching.pairs import match_pair, photo_threshold_px
from pipeline.types import Features


def exact_pair(n, seed=0):
    """Features of ``n`` points seen exactly by two cameras, each point with its own
    descriptor in both images (every putative match is right and mutual)."""
    rng = np.random.default_rng(seed)
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    a = 0.2
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    t = np.array([-1.0, 0.1, 0.05])
    X = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(4, 8, n)]

    def proj(R_, t_):
        p = (K @ (R_ @ X.T + t_[:, None])).T
        return (p[:, :2] / p[:, 2:]).astype(np.float32)

    desc = (np.eye(n, 16) * 10 + rng.uniform(0, 1, (n, 16))).astype(np.float32)
    f_i = Features(proj(np.eye(3), np.zeros(3)), desc, np.ones(n, np.float32), "sift")
    f_j = Features(proj(R, t), desc.copy(), np.ones(n, np.float32), "sift")
    return f_i, f_j, K


@pytest.mark.parametrize("known", [True, False])
def test_exactly_min_matches_is_enough(known):
    f_i, f_j, K = exact_pair(8)
    pm = match_pair(0, 1, f_i, f_j, K, K, intrinsics_known=known, min_matches=8)
    assert pm.reason == ""
    np.testing.assert_array_equal(pm.pairs, np.stack([np.arange(8)] * 2, 1))
    assert pm.n_putative == 8


def test_one_match_short_of_min_matches_is_empty():
    f_i, f_j, K = exact_pair(8)
    pm = match_pair(0, 1, f_i, f_j, K, K, min_matches=9)
    assert len(pm.pairs) == 0 and "too few putative matches (8 < 9)" in pm.reason


def test_ratio_one_is_allowed():
    f_i, f_j, K = exact_pair(12)
    assert len(match_pair(0, 1, f_i, f_j, K, K, ratio=1.0).pairs) == 12


@pytest.mark.parametrize("swap", [False, True])
def test_threshold_none_scales_with_the_larger_image(monkeypatch, swap):
    seen = []
    real = matching.epipolar_filter

    def spy(*args):
        seen.append(args[5])
        return real(*args)

    monkeypatch.setattr(matching, "epipolar_filter", spy)
    f_i, f_j, K = exact_pair(12)
    sizes = ((640, 480), (1600, 1200))
    if swap:
        match_pair(1, 0, f_j, f_i, K, K, threshold_px=None, sizes=sizes[::-1])
    else:
        match_pair(0, 1, f_i, f_j, K, K, threshold_px=None, sizes=sizes)
    assert seen == [photo_threshold_px(1600, 1200)] == [2.0]
