"""COLMAP's SIFT and COLMAP's matcher on given pairs (pipeline.colmap.sift), and the
pipeline's use of them: the batch over all edges equals edge-by-edge matching (a robot in its
own process matches as the simulator does)."""

import numpy as np
import pytest

from pipeline.colmap.sift import DESCRIPTOR_SCALE, sift
from pipeline.errors import InputError
from pipeline.inputs.photos import load_folder
from pipeline.matching.features import extract, extract_all
from pipeline.matching.pairs import lowe_ratios, match_edges, match_pair, sampson_error_px


@pytest.fixture(scope="module")
def three_views(sceaux_small):
    return load_folder(sceaux_small, max_size=400)[:3]


def test_sift_keypoints_descriptors_and_conventions(three_views):
    from pipeline.matching.features import _gray

    got = sift(_gray(three_views[0]), max_features=500)
    n = len(got.keypoints)
    assert n >= 400 and got.descriptors.shape == (n, 128) and got.scales.shape == (n,)
    # unit length, stored by COLMAP as uint8 of 512 d: the floats are exact multiples
    assert np.allclose(np.linalg.norm(got.descriptors, axis=1), 1.0, atol=0.02)
    q = got.descriptors * DESCRIPTOR_SCALE
    assert np.array_equal(q, np.round(q))
    h, w = three_views[0].image.shape[:2]
    assert (got.keypoints >= -0.5).all() and (got.keypoints[:, 0] <= w - 0.5).all()
    with pytest.raises(InputError, match="gray"):
        sift(three_views[0].image)


def test_colmap_sift_feature_method_merges_orientations(three_views):
    from scipy.spatial import cKDTree

    f = extract(three_views[0], "colmap-sift", 500)
    assert f.method == "colmap-sift" and f.descriptors.dtype == np.float32
    assert len(cKDTree(f.keypoints).query_pairs(0.5)) == 0  # one feature per location
    raw = extract(three_views[0], "colmap-sift", 500, merge_radius=0)
    assert len(raw) > len(f)  # COLMAP gives a second orientation at some locations


def test_batch_matching_equals_edge_by_edge_and_stays_on_the_edges(three_views):
    feats = extract_all(three_views, "colmap-sift", 1500)
    edges = np.array([[0, 1], [1, 2]])  # no (0, 2): those two never talk
    batch = match_edges(feats, three_views, edges, matcher="colmap", threshold_px=None)
    assert [(m.i, m.j) for m in batch] == [(0, 1), (1, 2)]
    for m in batch:
        v_i, v_j = three_views[m.i], three_views[m.j]
        one = match_pair(m.i, m.j, feats[m.i], feats[m.j], v_i.K, v_j.K, True,
                         threshold_px=None, matcher="colmap", sizes=(v_i.size, v_j.size))
        assert np.array_equal(one.pairs, m.pairs) and one.n_putative == m.n_putative
        assert len(m.pairs) >= 15 and m.reason == ""
        # one-to-one, ratio test passed, inliers within COLMAP's 4 px of the pair's geometry
        assert len(np.unique(m.pairs[:, 0])) == len(m.pairs) == len(np.unique(m.pairs[:, 1]))
        assert (m.ratio <= 0.8 + 1e-4).all()
        assert np.median(m.epipolar_error) < 4.0


def test_lowe_ratios_against_a_brute_force_reference():
    rng = np.random.default_rng(0)
    d_i = rng.random((20, 8)).astype(np.float32)
    d_j = rng.random((30, 8)).astype(np.float32)
    dist = np.linalg.norm(d_i[:, None] - d_j[None], axis=2)
    s = dist.argmin(1)
    pairs = np.c_[np.arange(20), s]
    second = np.sort(dist, axis=1)[:, 1]
    want = dist[np.arange(20), s] / second
    assert np.allclose(lowe_ratios(d_i, d_j, pairs, rows_per_block=7), want, atol=1e-4)


def test_colmap_matcher_refuses_binary_descriptors(three_views):
    feats = extract_all(three_views[:2], "orb", 300)
    with pytest.raises(InputError, match="SIFT descriptors"):
        match_edges(feats, three_views[:2], [[0, 1]], matcher="colmap")
    with pytest.raises(InputError, match="matcher"):
        match_edges(feats, three_views[:2], [[0, 1]], matcher="flann")


def test_sampson_error_of_colmap_geometry_is_in_opencv_pixels(three_views):
    # the fundamental matrix read back from COLMAP is moved to the OpenCV convention: its
    # inliers' Sampson errors stay within the 4 px threshold it was estimated with
    from pipeline.colmap.sift import match_pairs

    feats = extract_all(three_views[:2], "colmap-sift", 1500)
    cams = [(v.K, v.size, True, True) for v in three_views[:2]]
    (vp,) = match_pairs(["a", "b"], [f.keypoints for f in feats],
                        [f.descriptors for f in feats], cams, [[0, 1]], threads=1)
    assert vp.F is not None and len(vp.pairs) >= 15
    err = sampson_error_px(vp.F, feats[0].keypoints[vp.pairs[:, 0]].astype(float),
                           feats[1].keypoints[vp.pairs[:, 1]].astype(float))
    assert np.percentile(err, 95) < 4.0


def test_colmap_matching_runs_on_one_thread_unless_told(three_views, monkeypatch):
    """On several threads COLMAP's CPU matching does not give the same matches from call to
    call; run-images' matching (match_edges, no ``workers``) asks for one thread."""
    import pycolmap

    seen = []
    real = pycolmap.match_image_pairs

    def spy(*args, matching_options, **kwargs):
        seen.append(matching_options.num_threads)
        return real(*args, matching_options=matching_options, **kwargs)
    monkeypatch.setattr(pycolmap, "match_image_pairs", spy)
    feats = extract_all(three_views, "colmap-sift", 500)
    edges = np.array([[0, 1], [1, 2]])
    match_edges(feats, three_views, edges, matcher="colmap", threshold_px=None)
    match_edges(feats, three_views, edges, matcher="colmap", threshold_px=None, workers=2)
    assert seen == [1, 2]
