"""Ground truth: 3D points from depth, good links with the depth test, true pairs."""

import numpy as np
import pytest

import data_synth
from data_synth.ground_truth import (
    DEPTH_EPS,
    _transfer,
    good_links,
    points_from_keypoints,
    sample_depth,
    true_pairs,
)
from data_synth.renderer import project
from pipeline.errors import InputError

SIZE = (320, 240)


@pytest.fixture(scope="module")
def formation():
    return data_synth.render("d", seed=0, size=SIZE)


@pytest.fixture(scope="module")
def samples(formation):
    rng = np.random.default_rng(0)
    return rng.uniform([0, 0], [SIZE[0] - 1, SIZE[1] - 1], (3000, 2))


def test_points_from_keypoints_reproject_to_themselves(formation, samples):
    v = formation.views[1]
    X, valid = points_from_keypoints(v, samples)
    assert valid.all()  # the scene fills the view
    xy, z = project(v.K, v.R, v.t, X)
    np.testing.assert_allclose(xy, samples, atol=1e-6)
    np.testing.assert_allclose(z, sample_depth(v.depth, samples), rtol=1e-9)


def test_good_links_agree_with_depth_in_both_views(formation, samples):
    i, j = 0, 3
    vi, vj = formation.views[i], formation.views[j]
    X, _ = points_from_keypoints(vi, samples)
    p, z = project(vj.K, vj.R, vj.t, X)
    inside = (p[:, 0] >= 0) & (p[:, 0] <= SIZE[0] - 1) & (p[:, 1] >= 0) & (p[:, 1] <= SIZE[1] - 1)
    d = sample_depth(vj.depth, p)
    seen = inside & (np.abs(d - z) <= DEPTH_EPS * z)
    hidden = inside & (d < (1 - 3 * DEPTH_EPS) * z)  # something nearer covers the point in j
    assert seen.sum() > 1000 and hidden.sum() > 10
    # exact transfer: good exactly where the depth test passes in view j ...
    g = good_links(formation, i, samples[inside], j, p[inside])
    np.testing.assert_array_equal(g, seen[inside])
    # ... and the good ones are consistent the other way round: depth of j's point agrees too
    Xj, valid_j = points_from_keypoints(vj, p[seen])
    assert valid_j.all()
    gap = np.linalg.norm(Xj - X[seen], axis=1)
    assert (gap <= 1.25 * DEPTH_EPS * z[seen]).all()  # ray length <= 1.25 z in this camera
    assert np.median(gap) < 1e-3  # same plane: 1/z interpolation is exact
    # 5 px off is never good; 1 px off still is (tolerance 2 px)
    assert not good_links(formation, i, samples[seen], j, p[seen] + [0.0, 5.0]).any()
    assert good_links(formation, i, samples[seen], j, p[seen] + [1.0, 0.0]).mean() > 0.98


def test_good_links_symmetric(formation, samples):
    p, vis = _transfer(formation.views[0], samples, formation.views[2])
    a = good_links(formation, 0, samples[vis], 2, p[vis] + 0.8)
    b = good_links(formation, 2, p[vis] + 0.8, 0, samples[vis])
    np.testing.assert_array_equal(a, b)


def test_true_pairs_recovers_constructed_correspondences(formation, samples):
    rng = np.random.default_rng(1)
    i, j = 1, 2
    xy_i = samples[:800]
    p, vis = _transfer(formation.views[i], xy_i, formation.views[j])
    # camera j detected the visible points (with 0.3 px noise) plus 300 unrelated keypoints,
    # in shuffled order
    extra = rng.uniform([0, 0], [SIZE[0] - 1, SIZE[1] - 1], (300, 2))
    xy_j = np.concatenate([p[vis] + rng.normal(0, 0.3, (vis.sum(), 2)), extra])
    perm = rng.permutation(len(xy_j))
    xy_j = xy_j[perm]
    pos_of = np.argsort(perm)  # new index of old row k
    expected = np.column_stack([np.flatnonzero(vis), pos_of[:vis.sum()]])
    tp = true_pairs(formation, i, xy_i, j, xy_j)
    # one-to-one
    assert len(np.unique(tp[:, 0])) == len(tp) and len(np.unique(tp[:, 1])) == len(tp)
    # every returned pair is a good link
    assert good_links(formation, i, xy_i[tp[:, 0]], j, xy_j[tp[:, 1]]).all()
    got = {tuple(r) for r in tp.tolist()}
    want = {tuple(r) for r in expected.tolist()}
    # the random extra points may steal a few (they are mutual nearest by chance)
    assert len(got & want) >= 0.97 * len(want)
    assert len(got - want) <= 0.03 * len(want)


def test_true_pairs_empty_inputs(formation):
    assert true_pairs(formation, 0, np.zeros((0, 2)), 1, np.ones((5, 2))).shape == (0, 2)


def test_ground_truth_bad_input(formation):
    with pytest.raises(InputError, match="shape"):
        good_links(formation, 0, np.zeros((3, 3)), 1, np.zeros((3, 2)))
    with pytest.raises(InputError, match="row by row"):
        good_links(formation, 0, np.zeros((3, 2)), 1, np.zeros((4, 2)))
    with pytest.raises(InputError, match="camera 9"):
        good_links(formation, 0, np.zeros((1, 2)), 9, np.zeros((1, 2)))


@pytest.mark.parametrize("tol", [float("nan"), -1.0, 0, float("inf"), "2", True])
def test_a_tolerance_that_is_not_a_positive_number_of_pixels_is_named(formation, tol):
    xy = np.array([[10.0, 10.0], [50.0, 40.0]])
    for judge in (good_links, true_pairs):
        with pytest.raises(InputError, match=f"tol_px must be .* got {tol!r}"):
            judge(formation, 0, xy, 1, xy, tol_px=tol)


@pytest.mark.parametrize("cam", [1.5, "1", True, -1, 6])
def test_a_camera_that_is_not_an_index_of_the_formation_is_named(formation, cam):
    xy = np.array([[10.0, 10.0]])
    with pytest.raises(InputError, match=f"camera {cam!r} is not a camera"):
        good_links(formation, 0, xy, cam, xy)


def _sample_depth_whole_map(depth, xy):
    """The reference: ``1/z`` of the whole map first, then the same sampling rule."""
    H, W = depth.shape
    out = np.full(len(xy), np.inf)
    x, y = xy[:, 0], xy[:, 1]
    inside = (x >= -0.5) & (x <= W - 0.5) & (y >= -0.5) & (y <= H - 0.5)
    x, y = x[inside], y[inside]
    with np.errstate(divide="ignore"):
        inv = np.where(np.isfinite(depth), 1.0 / depth.astype(np.float64), 0.0)
    nearest = inv[np.clip(np.rint(y).astype(int), 0, H - 1), np.clip(np.rint(x).astype(int), 0, W - 1)]
    x0 = np.clip(np.floor(x).astype(int), 0, W - 2)
    y0 = np.clip(np.floor(y).astype(int), 0, H - 2)
    fx, fy = np.clip(x - x0, 0, 1), np.clip(y - y0, 0, 1)
    q00, q10, q01, q11 = inv[y0, x0], inv[y0, x0 + 1], inv[y0 + 1, x0], inv[y0 + 1, x0 + 1]
    q = np.stack([q00, q10, q01, q11])
    lo, hi = q.min(axis=0), q.max(axis=0)
    planar = (lo > 0) & (hi - lo <= 0.05 * hi) & (np.abs(q00 + q11 - q10 - q01) <= 1e-3 * hi)
    bil = q00 * (1 - fx) * (1 - fy) + q10 * fx * (1 - fy) + q01 * (1 - fx) * fy + q11 * fx * fy
    inv_s = np.where(planar, bil, nearest)
    with np.errstate(divide="ignore"):
        out[inside] = np.where(inv_s > 0, 1.0 / inv_s, np.inf)
    return out


def test_sample_depth_converts_only_sampled_pixels_bit_for_bit(formation):
    rng = np.random.default_rng(3)
    depth = formation.views[2].depth.copy()
    depth[:40] = np.inf  # sky and depth edges too
    xy = np.concatenate([rng.uniform(-2, [SIZE[0] + 1, SIZE[1] + 1], (4000, 2)),
                         np.array([[-0.5, -0.5], [SIZE[0] - 0.5, SIZE[1] - 0.5], [10.0, 39.5]])])
    np.testing.assert_array_equal(sample_depth(depth, xy), _sample_depth_whole_map(depth, xy))


def test_true_pairs_are_remembered_per_keypoints_and_tolerance(formation, samples):
    f = data_synth.render("d", seed=0, size=SIZE)  # a fresh formation: empty memory
    xy_i = samples[:800]
    X, _ = points_from_keypoints(f.views[0], xy_i)
    xy_j, _ = project(f.views[1].K, f.views[1].R, f.views[1].t, np.nan_to_num(X))
    first = true_pairs(f, 0, xy_i, 1, xy_j)
    assert len(first) > 100 and len(f._truth_cache) == 1
    first[:] = -1  # the caller's copy, not the remembered one
    again = true_pairs(f, 0, xy_i, 1, xy_j)
    assert len(f._truth_cache) == 1
    np.testing.assert_array_equal(again, true_pairs(formation, 0, xy_i, 1, xy_j))
    # other keypoints or another tolerance are new questions, answered afresh
    moved = xy_j + 3.0
    assert len(true_pairs(f, 0, xy_i, 1, moved)) < len(again)
    assert len(true_pairs(f, 0, xy_i, 1, xy_j, tol_px=0.01)) <= len(again)
    assert len(f._truth_cache) == 3
