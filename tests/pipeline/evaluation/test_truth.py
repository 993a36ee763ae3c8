"""Homography ground truth: H_ij from H_1k, mutual reprojection, true pairs, rescaling."""

from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.evaluation.truth import (
    _map,
    apply_homography,
    homography_link_truth,
    homography_true_pairs,
    pair_homography,
    read_homographies,
)
from pipeline.types import Links

GRAF_SMALL = Path(__file__).resolve().parents[2] / "data" / "graffiti_small"
GRAF_FULL = GRAF_SMALL / "original_homographies"  # the data set's own files, 800x640


def _shift(dx, dy):
    return np.array([[1.0, 0, dx], [0, 1.0, dy], [0, 0, 1.0]])


def test_pair_homography_composes():
    H1 = np.stack([np.eye(3), _shift(5, 0), _shift(5, 7)])
    np.testing.assert_allclose(pair_homography(H1, 1, 2), _shift(0, 7))
    np.testing.assert_allclose(apply_homography(_shift(1, 2), np.array([[0.0, 0.0]])), [[1, 2]])


def test_link_truth_is_mutual_within_tolerance():
    H1 = np.stack([np.eye(3), _shift(10, 0)])
    kp0 = np.array([[0.0, 0.0], [20.0, 5.0], [40.0, 40.0]])
    kp1 = np.array([[10.0, 0.0], [31.5, 5.0], [55.0, 40.0]])  # errors 0, 1.5, 5 px
    links = Links([0, 0, 0], [0, 1, 2], [1, 1, 1], [0, 1, 2])
    scales = np.ones((2, 2))
    assert homography_link_truth([kp0, kp1], links, H1, scales, 2.0).tolist() == [True, True, False]
    assert homography_link_truth([kp0, kp1], links, H1, scales, 1.0).tolist() == [True, False, False]


def test_true_pairs_are_mutual_nearest_one_to_one():
    H1 = np.stack([np.eye(3), _shift(10, 0)])
    kp0 = np.array([[0.0, 0.0], [20.0, 5.0], [100.0, 100.0]])
    kp1 = np.array([[10.0, 0.5], [10.0, 1.0], [30.0, 5.0]])  # two candidates for kp0[0]
    tp = homography_true_pairs([kp0, kp1], H1, np.ones((2, 2)), 2.0)
    assert tp.tolist() == [[0, 3], [1, 5]]  # global ids: camera 1 starts at 3


def test_downscaled_copy_agrees_with_full_resolution():
    """The 400 px test homographies map like the originals in the OpenCV pixel convention."""
    H_small = read_homographies(GRAF_SMALL, 6)
    H_full = read_homographies(GRAF_FULL, 6)
    pts = np.array([[10.0, 20.0], [200.0, 150.0], [390.0, 300.0]])
    via_small = _map(H_small, np.ones((6, 2)), 0, 4, pts)
    via_full = _map(H_full, np.full((6, 2), 0.5), 0, 4, pts)
    np.testing.assert_allclose(via_small, via_full, atol=1e-3)


def test_missing_or_bad_homography_file(tmp_path):
    with pytest.raises(InputError, match="H1to2p.txt"):
        read_homographies(tmp_path, 2)
    (tmp_path / "H1to2p.txt").write_text("1 0 0\n0 1 0\n")
    with pytest.raises(InputError, match="invertible 3 x 3"):
        read_homographies(tmp_path, 2)
    (tmp_path / "H1to2p.txt").write_text("nan 0 0\n0 1 0\n0 0 1\n")
    with pytest.raises(InputError, match="non-finite value"):
        read_homographies(tmp_path, 2)
    (tmp_path / "H1to2p.txt").write_text("1 2 3\n2 4 6\n0 0 0\n")
    with pytest.raises(InputError, match="singular"):
        read_homographies(tmp_path, 2)
