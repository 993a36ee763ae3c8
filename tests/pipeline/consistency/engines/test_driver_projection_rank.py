"""resolve_conflicts with a projection that is no finite camera (a zero matrix, a singular K R):
an InputError naming the camera, not every set through it cut."""

import numpy as np
import pytest

from pipeline.consistency import resolve_conflicts
from pipeline.errors import InputError
from pipeline.types import Links

M = np.array([2, 1, 1, 1])
COMM = np.array([[0, 1], [1, 2], [2, 3], [0, 3]])
# the README's Fig. 1 chain: 0:0 - 1:0 - 2:0 - 3:0 - 0:1
LINKS = Links(np.array([0, 1, 2, 0]), np.array([0, 0, 0, 1]), np.array([1, 2, 3, 3]),
              np.array([0, 0, 0, 0]))
K = np.array([[100.0, 0, 50], [0, 100, 50], [0, 0, 1]])
KP = [np.array([[50.0, 50], [60, 50]]), np.array([[50.0, 50]]), np.array([[50.0, 50]]),
      np.array([[50.0, 50]])]


def _P(x):
    return K @ np.c_[np.eye(3), [-x, 0.0, 0.0]]


@pytest.mark.parametrize("bad", [np.zeros((3, 4)), np.c_[np.eye(3)[:, [0, 1, 1]], np.ones(3)]])
def test_a_singular_projection_is_refused(bad):
    P = [_P(0.0), bad, _P(2.0), _P(3.0)]
    with pytest.raises(InputError, match=r"projection of camera 1: .*singular"):
        resolve_conflicts(M, COMM, LINKS, resolution="evidence", keypoints=KP, projections=P)


def test_finite_cameras_and_unknown_ones_still_run():
    P = [_P(0.0), None, _P(2.0), _P(3.0)]
    res = resolve_conflicts(M, COMM, LINKS, resolution="evidence", keypoints=KP, projections=P)
    assert res.deleted.any()
