"""A frame file of an online step's robot (pipeline.team.online_match.load_frame) holding an
image of one pixel row or column, or more than one ``intrinsics_known`` value, is refused,
naming the file and what is wrong."""

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.team.online_match import load_frame


@pytest.mark.parametrize("shape", [(1, 32, 3), (24, 1), (1, 1)])
def test_an_image_thinner_than_two_pixels_is_refused(tmp_path, shape):
    path = tmp_path / "frame-0.npz"
    np.savez(path, image=np.zeros(shape, np.uint8), K=np.eye(3),
             intrinsics_known=np.array([True]))
    with pytest.raises(InputError, match=rf"frame-0\.npz': image has shape "
                                         rf"\({shape[0]}, {shape[1]}.*at least 2 x 2 pixels"):
        load_frame(path, "frame-0")


def test_an_image_of_two_by_two_pixels_is_taken(tmp_path):
    path = tmp_path / "frame-0.npz"
    np.savez(path, image=np.zeros((2, 2), np.uint8), K=np.eye(3),
             intrinsics_known=np.array([False]))
    view = load_frame(path, "frame-0")
    assert view.image.shape == (2, 2) and view.intrinsics_known is False and view.R is None


def test_more_than_one_intrinsics_known_value_is_refused(tmp_path):
    path = tmp_path / "frame-0.npz"
    np.savez(path, image=np.zeros((4, 4), np.uint8), K=np.eye(3),
             intrinsics_known=np.array([True, False]))
    with pytest.raises(InputError, match=r"frame-0\.npz': intrinsics_known \[True, False\] is "
                                         r"not one true/false value"):
        load_frame(path, "frame-0")
