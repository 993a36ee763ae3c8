"""The descriptor forms of the feature packets on values the extractors do not produce: a
float descriptor travels as bytes only when every value is an integer in 0..255, and a
robot asked for RootSIFT of binary or COLMAP descriptors matches them as they are."""

import numpy as np
import pytest

from pipeline.matching.packed import (
    extract_raw,
    matching_descriptors,
    pack_features,
    unpack_features,
)


@pytest.mark.parametrize("values", [
    [[-3.0, 4.0], [0.0, 255.0]],     # integral but negative
    [[0.0, 256.0], [1.0, 2.0]],      # integral but above a byte
    [[0.5, 3.0], [1.0, 2.0]],        # within a byte but not integral
])
def test_float_descriptors_outside_bytes_travel_unchanged(values):
    d = np.array(values, np.float32)
    packed = pack_features(np.zeros((2, 2), np.float32), d, False)
    assert packed["descriptors"].dtype == np.float32
    _, got = unpack_features(packed)
    np.testing.assert_array_equal(got, d)


def test_byte_valued_float_descriptors_travel_as_bytes_and_come_back_equal():
    d = np.array([[0.0, 255.0, 17.0], [3.0, 254.0, 1.0]], np.float32)
    packed = pack_features(np.zeros((2, 2), np.float32), d, False)
    assert packed["descriptors"].dtype == np.uint8
    _, got = unpack_features(packed)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, d)


def test_rootsift_leaves_binary_descriptors_as_they_are():
    d = np.array([[0, 255, 17], [3, 254, 1]], np.uint8)
    got = matching_descriptors(d, True)
    assert got.dtype == np.uint8
    np.testing.assert_array_equal(got, d)


def test_colmap_sift_is_matched_without_a_second_rootsift():
    # COLMAP's descriptors are L1-rooted already: the rootsift option does not apply
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, (120, 160)).astype(np.uint8)
    opts = {"features": "colmap-sift", "max_features": 100, "rootsift": True}
    _, rootsift = extract_raw(img, opts, 0.5)
    assert rootsift is False
    _, rootsift = extract_raw(img, dict(opts, features="sift"), 0.5)
    assert rootsift is True
