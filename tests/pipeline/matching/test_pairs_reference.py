"""The putative matches, Lowe ratios and Sampson errors of :mod:`pipeline.matching.pairs`
against independent computations: a brute force over every descriptor pair in float64, and
the Sampson error from its definition (a numerical gradient of the epipolar constraint)."""

import numpy as np
import pytest

from pipeline.matching.pairs import (
    epipolar_filter,
    lowe_ratios,
    mutual_ratio_matches,
    sampson_error_px,
)


def _dist(a, b):
    """Exact distances, float64: L2, or Hamming on the bits of uint8 rows."""
    if a.dtype == np.uint8:
        return (np.unpackbits(a, axis=1)[:, None, :]
                != np.unpackbits(b, axis=1)[None, :, :]).sum(-1).astype(np.float64)
    a, b = a.astype(np.float64), b.astype(np.float64)
    return np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1))


def _side(dist):
    """For each row: nearest column (first on ties) and its ratio to the second nearest
    (no second: 0; both 0, two identical candidates: 1)."""
    out_nn, out_ratio = [], []
    for row in dist:
        nn = int(np.argmin(row))
        others = np.delete(row, nn)
        d1 = row[nn]
        if others.size == 0:
            ratio = 0.0
        elif others.min() == 0:  # then d1 = 0 too
            ratio = 1.0
        else:
            ratio = d1 / others.min()
        out_nn.append(nn)
        out_ratio.append(ratio)
    return np.array(out_nn, dtype=np.int64), np.array(out_ratio)


def brute_force_matches(d_i, d_j, ratio):
    """Mutual nearest neighbours whose larger directional ratio is ``< ratio``."""
    if len(d_i) == 0 or len(d_j) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    dist = _dist(d_i, d_j)
    fwd, rf = _side(dist)
    bwd, rb = _side(dist.T)
    pairs, ratios = [], []
    for r, s in enumerate(fwd):
        link = max(rf[r], rb[s])
        if bwd[s] == r and link < ratio:
            pairs.append((r, s))
            ratios.append(link)
    return np.array(pairs, dtype=np.int64).reshape(-1, 2), np.array(ratios)


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
@pytest.mark.parametrize("seed", range(30))
def test_mutual_ratio_matches_equal_a_brute_force(seed, dtype):
    rng = np.random.default_rng(seed)
    n_i, n_j = rng.integers(0, 7, 2)
    # few distinct values: ties, identical descriptors and one or two candidates are frequent
    d_i = rng.integers(0, 3, (n_i, 4)).astype(dtype)
    d_j = rng.integers(0, 3, (n_j, 4)).astype(dtype)
    for ratio in (0.5, 0.8, 1.0):
        p, r = mutual_ratio_matches(d_i, d_j, ratio)
        bp, br = brute_force_matches(d_i, d_j, ratio)
        np.testing.assert_array_equal(p, bp)
        np.testing.assert_allclose(r, br, rtol=1e-6)


def test_a_single_candidate_passes_with_ratio_zero_and_two_close_ones_fail():
    d_i = np.array([[0.0, 0.0]], np.float32)
    p, r = mutual_ratio_matches(d_i, np.array([[3.0, 4.0]], np.float32), 0.8)
    np.testing.assert_array_equal(p, [[0, 0]])
    np.testing.assert_array_equal(r, [0.0])
    # two candidates at 5 and 5.1: the second one is a real alternative, the ratio 0.98 fails
    p, r = mutual_ratio_matches(d_i, np.array([[3.0, 4.0], [5.1, 0.0]], np.float32), 0.8)
    assert len(p) == 0
    # two identical best candidates (0 / 0): ambiguous, never kept
    p, r = mutual_ratio_matches(d_i, np.array([[0.0, 0.0], [0.0, 0.0]], np.float32), 1.0)
    assert len(p) == 0


def test_ratio_equal_to_the_threshold_is_refused():
    # d1 = 1, d2 = 2 exactly: the link ratio is 0.5, kept only below 0.5
    d_i = np.array([[0.0, 0.0]], np.float32)
    d_j = np.array([[1.0, 0.0], [2.0, 0.0]], np.float32)
    assert len(mutual_ratio_matches(d_i, d_j, 0.5)[0]) == 0
    np.testing.assert_array_equal(mutual_ratio_matches(d_i, d_j, 0.5001)[0], [[0, 0]])


def test_identical_unit_descriptors_match_each_other_with_ratio_zero():
    # RootSIFT-like unit vectors: |a|² + |b|² − 2 a·b of a descriptor with itself rounds to a
    # small negative float32 for many of them (and a small positive one for others); its
    # distance is 0 and it is its own match
    rng = np.random.default_rng(0)
    d = np.sqrt(rng.random((200, 128))).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    perm = rng.permutation(200)
    p, r = mutual_ratio_matches(d, d[perm], 0.8)
    inv = np.argsort(perm)
    np.testing.assert_array_equal(p, np.stack([np.arange(200), inv], 1))
    assert (r < 0.01).all()  # 0 up to the float32 rounding of the expanded square


def brute_force_lowe(d_i, d_j, pairs):
    dist = _dist(d_i, d_j)
    out = []
    for r, s in pairs:
        other = np.delete(dist[r], s).min()
        out.append(min(1.0, dist[r, s] / other) if other > 0 else 1.0)
    return np.array(out)


@pytest.mark.parametrize("block", [1, 3, 2048])
def test_lowe_ratios_equal_a_brute_force(block):
    rng = np.random.default_rng(1)
    d_i = rng.normal(size=(12, 16)).astype(np.float32)
    d_j = rng.normal(size=(9, 16)).astype(np.float32)
    # nearest neighbours and arbitrary pairs (ratio above 1, clipped)
    nn = _dist(d_i, d_j).argmin(1)
    pairs = np.concatenate([np.stack([np.arange(12), nn], 1),
                            np.stack([np.arange(12), rng.integers(0, 9, 12)], 1)])
    got = lowe_ratios(d_i, d_j, pairs, rows_per_block=block)
    np.testing.assert_allclose(got, brute_force_lowe(d_i, d_j, pairs), rtol=1e-4, atol=1e-6)
    assert (got[:12] < 1).all() and (got <= 1).all()




def sampson_by_definition(F, x_i, x_j, h=1e-4):
    """``c² / |∇c|²`` with ``c = x_jᵀ F x_i`` and its gradient over the four pixel coordinates
    taken by central differences (``c`` is bilinear: the differences are exact up to
    rounding)."""
    def c(a, b):
        return np.r_[b, 1.0] @ F @ np.r_[a, 1.0]
    out = []
    for a, b in zip(x_i, x_j, strict=True):
        g = []
        for k in range(2):
            e = np.zeros(2)
            e[k] = h
            g.append((c(a + e, b) - c(a - e, b)) / (2 * h))
            g.append((c(a, b + e) - c(a, b - e)) / (2 * h))
        out.append(abs(c(a, b)) / np.linalg.norm(g))
    return np.array(out)


def test_sampson_error_equals_its_definition_for_a_general_fundamental_matrix():
    rng = np.random.default_rng(2)
    # F of two cameras with different intrinsics and a general motion: neither symmetric nor
    # antisymmetric, so F and Fᵀ, or x_i and x_j, give different errors
    K_i = np.array([[500.0, 0, 300], [0, 480, 200], [0, 0, 1]])
    K_j = np.array([[350.0, 0, 160], [0, 360, 120], [0, 0, 1]])
    a = 0.3
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    t = np.array([1.0, 0.2, 0.1])
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(K_j).T @ tx @ R @ np.linalg.inv(K_i)
    x_i = rng.uniform(0, 400, (20, 2))
    x_j = rng.uniform(0, 300, (20, 2))
    np.testing.assert_allclose(sampson_error_px(F, x_i, x_j),
                               sampson_by_definition(F, x_i, x_j), rtol=1e-6)


def test_sampson_error_at_both_epipoles_is_infinite():
    # F x_i = 0 and Fᵀ x_j = 0: no gradient, the error is undefined and reported as inf
    # F = [e]_x: both epipoles at e = (1, 2, 1)
    e = np.array([1.0, 2.0, 1.0])
    F = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
    err = sampson_error_px(F, np.array([[1.0, 2.0]]), np.array([[1.0, 2.0]]))
    assert np.isinf(err).all()


def _two_camera_scene(seed=0, n=160):
    """Exact correspondences of random points seen by two cameras with different principal
    points (so ``K_i`` and ``K_j`` cannot be swapped unnoticed), the true ``F`` and the unit
    normal of each point's epipolar line in image ``j``."""
    rng = np.random.default_rng(seed)
    K_i = np.array([[500.0, 0, 330], [0, 500, 250], [0, 0, 1]])
    K_j = np.array([[500.0, 0, 300], [0, 500, 230], [0, 0, 1]])
    a = 0.2
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    t = np.array([-1.0, 0.1, 0.05])
    X = np.c_[rng.uniform(-2, 2, (n, 2)), rng.uniform(4, 8, n)]

    def proj(K, R_, t_):
        p = (K @ (R_ @ X.T + t_[:, None])).T
        return p[:, :2] / p[:, 2:]

    x_i, x_j = proj(K_i, np.eye(3), np.zeros(3)), proj(K_j, R, t)
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    F = np.linalg.inv(K_j).T @ tx @ R @ np.linalg.inv(K_i)
    line = np.c_[x_i, np.ones(n)] @ F.T
    normal = line[:, :2] / np.linalg.norm(line[:, :2], axis=1, keepdims=True)
    return K_i, K_j, x_i, x_j, F, normal


def test_essential_model_is_returned_as_a_pixel_fundamental_matrix():
    # F = K_j⁻ᵀ E K_i⁻¹: the exact correspondences lie on its epipolar lines in pixels
    K_i, K_j, x_i, x_j, _, _ = _two_camera_scene(n=100)
    inl, F, why = epipolar_filter(x_i, x_j, K_i, K_j, True, 1.0)
    assert why == "" and inl.all()
    assert sampson_error_px(F, x_i, x_j).max() < 1e-3


@pytest.mark.parametrize("seed", range(3))
def test_essential_threshold_is_in_pixels_like_the_fundamental_one(seed):
    # 100 exact correspondences and 60 moved 1.5 px off their epipolar line (Sampson error
    # about 1.06 px): at a 1 px threshold the fundamental matrix on pixels keeps them all, and
    # so must the essential matrix, whose threshold is the same 1 px divided by the focal
    K_i, K_j, x_i, x_j, _, normal = _two_camera_scene(seed)
    x_j = x_j.copy()
    x_j[100:] += 1.5 * normal[100:]
    in_f, _, _ = epipolar_filter(x_i, x_j, None, None, False, 1.0)
    in_e, _, _ = epipolar_filter(x_i, x_j, K_i, K_j, True, 1.0)
    assert in_f.all()
    np.testing.assert_array_equal(in_e, in_f)
