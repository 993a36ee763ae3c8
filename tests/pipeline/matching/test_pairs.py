import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pipeline.matching.pairs as matching
from pipeline.association import check_links
from pipeline.errors import InputError
from pipeline.matching.features import extract, extract_all
from pipeline.matching.pairs import (
    match_edges,
    match_pair,
    mutual_ratio_matches,
    sampson_error_px,
)
from pipeline.types import Features, Links, View

K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])


def textured(size=(320, 240), seed=0):
    rng = np.random.default_rng(seed)
    w, h = size
    img = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), 2.0)
    return cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def plane_homography(angle_deg=4.0, tx=0.15, depth=2.0):
    """``H = K (R + t nᵀ / d) K⁻¹`` of the plane ``z = d`` seen from camera 0, camera 1 = R x + t."""
    a = np.deg2rad(angle_deg)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    t = np.array([tx, 0.02, 0.0])
    return K @ (R + np.outer(t, [0, 0, 1]) / depth) @ np.linalg.inv(K)


def plane_pair(seed=0):
    """Two views of one textured plane and the homography mapping view 0 to view 1."""
    base = textured(seed=seed)
    H = plane_homography()
    other = cv2.warpPerspective(base, H, (320, 240), flags=cv2.INTER_LINEAR)
    return [View("cam00", base, K.copy()), View("cam01", other, K.copy())], H


def transfer_error(H, x0, x1):
    p = np.c_[x0, np.ones(len(x0))] @ H.T
    return np.linalg.norm(p[:, :2] / p[:, 2:] - x1, axis=1)


@pytest.fixture(scope="module")
def pair():
    views, H = plane_pair()
    return views, H, extract_all(views, "sift", 800)


# ------------------------------------------------------------------ putative matches


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 40), st.integers(0, 40), st.integers(0, 2**31 - 1),
       st.sampled_from([np.float32, np.uint8]))
def test_mutual_ratio_matches_one_to_one_and_symmetric(n_i, n_j, seed, dtype):
    rng = np.random.default_rng(seed)
    # few distinct values: ties and identical descriptors are frequent
    d_i = rng.integers(0, 4, (n_i, 8)).astype(dtype)
    d_j = rng.integers(0, 4, (n_j, 8)).astype(dtype)
    p, r = mutual_ratio_matches(d_i, d_j, 0.8)
    assert p.shape == (len(r), 2) and (r < 0.8).all()
    assert len(np.unique(p[:, 0])) == len(p) and len(np.unique(p[:, 1])) == len(p)
    q, rq = mutual_ratio_matches(d_j, d_i, 0.8)
    order_p, order_q = np.lexsort(p.T[::-1]), np.lexsort(q[:, ::-1].T[::-1])
    np.testing.assert_array_equal(p[order_p], q[:, ::-1][order_q])
    np.testing.assert_allclose(r[order_p], rq[order_q])


def test_mutual_ratio_matches_hand_computed():
    d_i = np.array([[0, 0], [10, 0], [0, 10]], np.float32)
    d_j = np.array([[0, 1], [10, 0.5], [5, 5]], np.float32)
    p, r = mutual_ratio_matches(d_i, d_j, 0.8)
    np.testing.assert_array_equal(p, [[0, 0], [1, 1]])
    # (0,0): forward 1/sqrt(50), backward 1/9; (1,1): forward 0.5/sqrt(50), backward
    # 0.5/sqrt(100.25); the link keeps the larger one. Feature 2 of i has no mutual partner.
    np.testing.assert_allclose(r, [1 / np.sqrt(50), 0.5 / np.sqrt(50)], rtol=1e-5)


def test_sampson_error_hand_computed():
    # rectified stereo: epipolar lines are rows, error = |y_i - y_j| / sqrt(2)
    F = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    err = sampson_error_px(F, np.array([[10.0, 5], [3, 7]]), np.array([[40.0, 5], [1, 10]]))
    np.testing.assert_allclose(err, [0, 3 / np.sqrt(2)])


# ------------------------------------------------------------------ one edge


def test_easy_pair_precision(pair):
    views, H, f = pair
    m = match_pair(0, 1, f[0], f[1], K, K, True)
    assert m.reason == "" and len(m.pairs) >= 50
    err = transfer_error(H, f[0].keypoints[m.pairs[:, 0]], f[1].keypoints[m.pairs[:, 1]])
    assert (err < 2.0).mean() >= 0.95
    assert m.n_putative >= len(m.pairs)
    assert (m.epipolar_error <= 1.0 + 1e-3).all() and (m.ratio < 0.8).all()


def test_fundamental_when_intrinsics_unknown(pair):
    views, H, f = pair
    m = match_pair(0, 1, f[0], f[1], None, None, intrinsics_known=False)
    assert len(m.pairs) >= 50
    err = transfer_error(H, f[0].keypoints[m.pairs[:, 0]], f[1].keypoints[m.pairs[:, 1]])
    assert (err < 2.0).mean() >= 0.95


def test_swapped_call_gives_the_same_association(pair):
    views, H, f = pair
    a = match_pair(0, 1, f[0], f[1], K, K, True)
    b = match_pair(1, 0, f[1], f[0], K, K, True)
    assert (b.i, b.j) == (0, 1)
    np.testing.assert_array_equal(a.pairs, b.pairs)


def test_unrelated_images_give_empty_association_with_reason():
    f = extract_all([textured(seed=1), textured(seed=2)], "sift", 400)
    m = match_pair(0, 1, f[0], f[1], K, K, True)
    assert len(m.pairs) == 0 and m.pairs.shape == (0, 2)
    assert m.reason.startswith(("too few putative matches", "too few epipolar inliers"))


def test_zero_feature_camera_gives_empty_association(pair):
    views, H, f = pair
    blank = extract(np.zeros((240, 320), np.uint8))
    m = match_pair(0, 1, f[0], blank, K, K, True)
    assert len(m.pairs) == 0 and m.reason == "too few putative matches (0 < 8)"


def test_mixed_descriptors_rejected(pair):
    views, H, f = pair
    orb = extract(views[1], "orb", 300)
    with pytest.raises(InputError, match="different descriptors"):
        match_pair(0, 1, f[0], orb, K, K, True)


def test_missing_intrinsics_rejected(pair):
    views, H, f = pair
    with pytest.raises(InputError, match="camera 1: intrinsics K"):
        match_pair(0, 1, f[0], f[1], K, None, True)


@pytest.mark.parametrize("kw,match", [({"ratio": 0}, "ratio"), ({"threshold_px": 0}, "threshold"),
                                      ({"min_matches": 5}, "min_matches")])
def test_bad_parameters(pair, kw, match):
    views, H, f = pair
    with pytest.raises(InputError, match=match):
        match_pair(0, 1, f[0], f[1], K, K, True, **kw)


def test_orb_pair_matches():
    views, H = plane_pair()
    f = extract_all(views, "orb", 800)
    m = match_pair(0, 1, f[0], f[1], K, K, True)
    err = transfer_error(H, f[0].keypoints[m.pairs[:, 0]], f[1].keypoints[m.pairs[:, 1]])
    assert len(m.pairs) >= 20 and (err < 2.0).mean() >= 0.9


# ------------------------------------------------------------------ all edges


@pytest.fixture(scope="module")
def four_cameras(pair):
    """Cameras 0 and 1 see the plane, 2 sees the same plane again (copy of 0), 3 is isolated."""
    views, H, f = pair
    v = views + [View("cam02", views[0].image, K.copy()), View("cam03", textured(seed=9), K.copy())]
    return v, f + [f[0], extract(v[3], "sift", 800)]


def test_only_comm_edges_are_matched(four_cameras, monkeypatch):
    views, f = four_cameras
    calls = []
    real = matching.match_pair

    def spy(i, j, *a, **k):
        calls.append((i, j))
        return real(i, j, *a, **k)

    monkeypatch.setattr(matching, "match_pair", spy)
    edges = [[1, 0], [2, 1]]  # camera 3 has no neighbour; 0-2 do not communicate
    out = match_edges(f, views, edges)
    assert sorted(calls) == [(0, 1), (1, 2)]
    assert [(m.i, m.j) for m in out] == [(0, 1), (1, 2)]
    links = Links.from_matches(out)
    pairs = set(zip(links.cam_i.tolist(), links.cam_j.tolist(), strict=True))
    assert pairs == {(0, 1), (1, 2)}
    check_links(links, [len(x) for x in f])  # one-to-one, i < j, no duplicates
    assert not np.isin(links.cam_i, 3).any() and not np.isin(links.cam_j, 3).any()


def test_every_association_is_one_to_one_and_stored_once(four_cameras):
    views, f = four_cameras
    out = match_edges(f, views, [[0, 1], [0, 2], [1, 2], [2, 3], [0, 3]])
    for m in out:
        assert m.i < m.j
        assert len(np.unique(m.pairs[:, 0])) == len(m.pairs) == len(np.unique(m.pairs[:, 1]))
    check_links(Links.from_matches(out), [len(x) for x in f])


def test_edges_naming_unknown_camera(four_cameras):
    views, f = four_cameras
    with pytest.raises(InputError, match=r"\(0, 7\) names an unknown camera"):
        match_edges(f, views, [[0, 1], [0, 7]])


def test_features_and_views_lengths_must_agree(four_cameras):
    views, f = four_cameras
    with pytest.raises(InputError, match="4 feature sets but 3 views"):
        match_edges(f, views[:3], [[0, 1]])


def test_no_edges_no_links(four_cameras):
    views, f = four_cameras
    assert match_edges(f, views, []) == []
    assert len(Links.from_matches([])) == 0


def test_threaded_edges_match_serial(four_cameras):
    views, f = four_cameras
    edges = [[0, 1], [1, 2], [0, 2]]
    a = match_edges(f, views, edges, workers=1)
    b = match_edges(f, views, edges, workers=2)  # one BLAS thread per product
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.pairs, y.pairs)
        np.testing.assert_array_equal(x.ratio, y.ratio)


def test_large_float_matrices_match_on_one_thread(four_cameras, monkeypatch):
    """Above the size limit float descriptors are matched serially (memory), with the same
    result."""
    import pipeline.matching.pairs as matching

    views, f = four_cameras
    edges = [[0, 1], [1, 2]]
    used = []
    monkeypatch.setattr(matching, "ThreadPoolExecutor",
                        lambda **kw: used.append(kw) or pytest.fail("threads used"))
    monkeypatch.setattr(matching, "PARALLEL_MAX_MATRIX_BYTES", 0)
    serial = match_edges(f, views, edges)
    assert used == []
    monkeypatch.undo()
    for x, y in zip(serial, match_edges(f, views, edges), strict=True):
        np.testing.assert_array_equal(x.pairs, y.pairs)


def test_empty_feature_sets_do_not_crash():
    e = Features(np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32),
                 np.zeros(0, np.float32), "sift")
    v = [View("a", np.zeros((10, 10), np.uint8), K), View("b", np.zeros((10, 10), np.uint8), K)]
    out = match_edges([e, e], v, [[0, 1]])
    assert len(out[0].pairs) == 0 and "0 < 8" in out[0].reason


# ------------------------------------------------------------------ rendered formation


def test_easy_rendered_pair_precision_against_ground_truth():
    import data_synth
    from pipeline.evaluation.links import link_truth

    f = data_synth.render("a", seed=0, size=(320, 240))
    feats = extract_all(f.views, "sift", 500)
    # neighbouring robots 0 and 1: a wide overlap, the easy case
    m = match_pair(0, 1, feats[0], feats[1], f.views[0].K, f.views[1].K, True)
    assert len(m.pairs) >= 50
    assert link_truth(f, feats, Links.from_matches([m])).mean() >= 0.95
