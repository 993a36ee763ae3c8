import cv2
import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.matching.features import extract, extract_all, merge_colocated, surf_available
from pipeline.types import View


def textured(size=(320, 240), seed=0):
    """Smoothed random blobs: plenty of corners and blobs for every detector, RGB uint8."""
    rng = np.random.default_rng(seed)
    w, h = size
    img = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), 2.0)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    return np.repeat(img[:, :, None], 3, axis=2)


def test_sift_shapes_and_types():
    f = extract(textured(), "sift", 500)
    assert 50 < len(f) <= 500
    assert f.keypoints.shape == (len(f), 2) and f.keypoints.dtype == np.float32
    assert f.descriptors.shape == (len(f), 128) and f.descriptors.dtype == np.float32
    assert f.scales.shape == (len(f),) and (f.scales > 0).all()
    assert f.method == "sift"


@pytest.mark.parametrize("method,dim", [("orb", 32), ("akaze", 61)])
def test_binary_methods(method, dim):
    f = extract(textured(), method, 300)
    assert 0 < len(f) <= 300
    assert f.descriptors.dtype == np.uint8 and f.descriptors.shape == (len(f), dim)


def test_view_gray_and_rgb_agree():
    img = textured()
    a = extract(View("cam00", img, np.eye(3)), "sift", 300)
    b = extract(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), "sift", 300)
    np.testing.assert_array_equal(a.keypoints, b.keypoints)


def test_colocated_sift_keypoints_are_merged():
    img = textured()
    raw = cv2.SIFT_create(nfeatures=500).detect(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY))
    xy = cv2.KeyPoint_convert(raw)
    assert len(np.unique(xy, axis=0)) < len(xy)  # SIFT does emit twins at one spot
    f = extract(img, "sift", 500)
    d = np.linalg.norm(f.keypoints[:, None] - f.keypoints[None], axis=2)
    np.fill_diagonal(d, np.inf)
    assert d.min() >= 0.5


def test_merge_colocated_hand_computed():
    xy = np.array([[0, 0], [0.2, 0], [0.4, 0.0], [5, 5], [5.1, 5]], np.float32)
    resp = np.array([1.0, 3.0, 2.0, 0.5, 0.7])
    # 0-1-2 is one chain (strongest: 1), 3-4 one pair (strongest: 4)
    np.testing.assert_array_equal(merge_colocated(xy, resp, 0.3), [1, 4])
    np.testing.assert_array_equal(merge_colocated(xy[:0], resp[:0]), [])


@pytest.mark.parametrize("method", ["sift", "orb", "akaze"])
def test_blank_image_gives_zero_features(method):
    f = extract(np.full((240, 320, 3), 128, np.uint8), method)
    assert len(f) == 0
    assert f.descriptors.shape[0] == 0 and f.keypoints.shape == (0, 2)


def test_unknown_method_names_the_choices():
    with pytest.raises(InputError, match="brisk.*sift, orb, akaze"):
        extract(textured(), "brisk")
    with pytest.raises(InputError, match="sift, orb, akaze"):
        extract_all([textured()], "brisk")


@pytest.mark.skipif(surf_available(), reason="this OpenCV build has SURF")
def test_surf_without_nonfree_names_alternatives():
    with pytest.raises(InputError, match="surf.*sift, orb, akaze"):
        extract(textured(), "surf")


@pytest.mark.parametrize("bad", ["not an image", np.zeros(10, np.uint8), np.zeros((0, 5), np.uint8),
                                 np.zeros((4, 4, 2), np.uint8)])
def test_bad_image_is_input_error(bad):
    with pytest.raises(InputError):
        extract(bad)


@pytest.mark.parametrize("bad", [0, -5, 2.5, True])
def test_bad_max_features(bad):
    with pytest.raises(InputError, match="max_features"):
        extract(textured(), "sift", bad)


def test_float_image_in_unit_range():
    img = textured()
    a = extract(img.astype(np.float32) / 255.0, "orb", 200)
    assert len(a) > 0


def test_extract_all_threads_match_serial():
    imgs = [textured(seed=s) for s in range(3)]
    a = extract_all(imgs, "sift", 300, workers=1)
    b = extract_all(imgs, "sift", 300, workers=2)
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.keypoints, fb.keypoints)
        np.testing.assert_array_equal(fa.descriptors, fb.descriptors)


def test_colmap_sift_in_forked_workers_matches_serial():
    # pycolmap's SIFT holds the GIL: extract_all forks workers for it; they must give the
    # serial run's features, in camera order
    imgs = [textured(size=(200, 160), seed=s) for s in range(3)]
    a = extract_all(imgs, "colmap-sift", 400, 0.5, workers=1)
    b = extract_all(imgs, "colmap-sift", 400, 0.5, workers=2)
    assert all(len(f) > 0 for f in a)
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.keypoints, fb.keypoints)
        np.testing.assert_array_equal(fa.descriptors, fb.descriptors)
        np.testing.assert_array_equal(fa.scales, fb.scales)


@pytest.mark.parametrize("method", ["sift", "orb", "akaze"])
@pytest.mark.parametrize("image", [np.zeros((1, 1), np.uint8), np.full((8, 300), 200, np.uint8)],
                         ids=["1x1", "8x300"])
def test_tiny_image_gives_zero_features(method, image):
    # regression: ORB raised a cv2.error from resize() on a 1x1 image
    f = extract(image, method)
    assert len(f) == 0 and f.descriptors.ndim == 2


@pytest.mark.parametrize("image", [
    np.ones((60, 80), bool),
    (textured()[:, :, 0].astype(np.uint16) * 257),
    np.full((60, 80), np.nan, np.float32),
    -np.ones((60, 80), np.int64),
], ids=["bool", "uint16", "nan", "negative-int"])
def test_other_dtypes_are_converted(image):
    f = extract(image, "sift", 200)
    assert f.descriptors.shape == (len(f), 128)


def test_uint16_scaled_not_saturated():
    img = textured()[:, :, 0]
    a = extract(img, "sift", 200)
    b = extract(img.astype(np.uint16) * 257, "sift", 200)
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
