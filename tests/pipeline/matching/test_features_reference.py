"""Feature extraction against independent computations: RootSIFT's formula, the image
conversions' formulas, label propagation over every keypoint pair for the merge of co-located
keypoints, and OpenCV's detector called directly for the feature budget."""

import cv2
import numpy as np
import pytest

from pipeline.matching.features import (
    _gray,
    extract,
    merge_colocated,
    photo_max_features,
    root_sift,
)


def textured(size=(320, 240), seed=0):
    rng = np.random.default_rng(seed)
    w, h = size
    img = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), 2.0)
    return cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def test_root_sift_is_the_square_root_of_the_l1_normalised_histogram():
    rng = np.random.default_rng(0)
    d = rng.integers(0, 255, (5, 128)).astype(np.float32)
    d[2] = 0.0
    want = np.sqrt(d / np.maximum(d.sum(1, keepdims=True), 1e-30))
    got = root_sift(d)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(got[[0, 1, 3, 4]], axis=1), 1.0, rtol=1e-6)
    assert not got[2].any()


def test_image_conversions_follow_their_formulas():
    v16 = np.array([[0, 256, 257, 65280, 65535, 51400]], np.uint16)
    np.testing.assert_array_equal(_gray(v16), v16 // 257)
    # float images in [0, 1]: x * 255 rounded to the nearest
    f = np.array([[0.0, 0.5, 1.0, 0.2, 0.999]])
    np.testing.assert_array_equal(_gray(f), np.floor(f * 255 + 0.5).astype(np.uint8))
    # not a number is black, infinities are clipped (the float image is not in [0, 1])
    g = np.array([[np.nan, np.inf, -np.inf, 7.6]])
    np.testing.assert_array_equal(_gray(g), [[0, 255, 0, 7]])


def brute_force_merge(xy, response, radius):
    """Groups of keypoints joined (transitively) by a distance ``<= radius``, from the dense
    distance matrix and label propagation; of each group the strongest, the lowest index
    among equally strong ones."""
    xy = np.asarray(xy, np.float64)
    n = len(xy)
    near = np.linalg.norm(xy[:, None] - xy[None], axis=-1) <= radius
    label = np.arange(n)
    while True:
        new = np.where(near, label[None, :], n).min(1)
        if np.array_equal(new, label):
            break
        label = new
    keep = []
    for g in np.unique(label):
        members = np.flatnonzero(label == g)
        keep.append(min(members.tolist(), key=lambda a: (-response[a], a)))
    return sorted(keep)


@pytest.mark.parametrize("seed", range(10))
def test_merge_colocated_equals_a_propagation_over_every_pair(seed):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 3, (40, 2))
    xy[20:30] = xy[:10] + rng.uniform(-0.2, 0.2, (10, 2))  # twins
    response = rng.integers(0, 4, 40).astype(float)          # ties are frequent
    got = merge_colocated(xy, response, 0.5)
    np.testing.assert_array_equal(got, brute_force_merge(xy, response, 0.5))


def _strongest_locations(kps, budget, radius=0.5):
    xy = cv2.KeyPoint_convert(kps).reshape(-1, 2)
    resp = np.array([k.response for k in kps])
    keep = np.asarray(brute_force_merge(xy, resp, radius))
    order = np.argsort(-resp[keep], kind="stable")[:budget]
    return np.sort(keep[order])


def test_akaze_budget_keeps_the_strongest_locations():
    img = textured(seed=1)
    kps, desc = cv2.xfeatures2d.AKAZE_create().detectAndCompute(img, None)
    assert len(kps) > 150
    keep = _strongest_locations(kps, 100)
    f = extract(img, "akaze", 100)
    np.testing.assert_array_equal(f.keypoints, cv2.KeyPoint_convert(kps)[keep])
    np.testing.assert_array_equal(f.descriptors, desc[keep])
    # a budget one short of the locations drops exactly the weakest one
    n_loc = len(_strongest_locations(kps, 10**6))
    assert len(extract(img, "akaze", n_loc - 1)) == n_loc - 1
    assert len(extract(img, "akaze", n_loc)) == n_loc


def test_sift_budget_after_merge_counts_locations():
    img = textured(seed=2)
    kps, desc = cv2.SIFT_create(nfeatures=0).detectAndCompute(img, None)
    keep = _strongest_locations(kps, 150)
    f = extract(img, "sift", 150, budget_after_merge=True)
    assert len(f) == 150
    np.testing.assert_array_equal(f.keypoints, cv2.KeyPoint_convert(kps)[keep])
    np.testing.assert_array_equal(f.descriptors, desc[keep])


def test_sift_contrast_threshold_reaches_the_detector():
    img = textured(seed=3)
    for thr in (0.02, 0.08):
        kps, _ = cv2.SIFT_create(nfeatures=5000, contrastThreshold=thr).detectAndCompute(img, None)
        xy = cv2.KeyPoint_convert(kps).reshape(-1, 2)
        resp = np.array([k.response for k in kps])
        want = xy[brute_force_merge(xy, resp, 0.5)]
        np.testing.assert_array_equal(extract(img, "sift", 5000, contrast_threshold=thr).keypoints,
                                      want)


def test_photo_budget_is_rounded_to_the_nearest():
    # 2000 * 700 * 500 / (640 * 480) = 2278.6
    assert photo_max_features(700, 500) == 2279
