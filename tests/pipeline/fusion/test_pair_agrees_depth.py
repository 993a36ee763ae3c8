"""Two observations agree (pipeline.fusion.local.pair_agrees) only on a point in front of
both cameras: the pixels of a point behind them satisfy the projection equations too."""

import numpy as np

from pipeline.fusion.local import pair_agrees

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
CENTRES = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])  # both looking along +z (R = I)


def pixels(X):
    p = (K @ (X[None] - CENTRES).T).T
    return p[:, :2] / p[:, 2:]


def agree(uv) -> bool:
    R = np.broadcast_to(np.eye(3), (1, 2, 3, 3))
    t = -CENTRES[None]  # t = -R C
    return bool(pair_agrees(uv[None], R, t, np.broadcast_to(K, (1, 2, 3, 3)), 2.0)[0])


def test_a_point_behind_both_cameras_is_no_agreement():
    X = np.array([0.3, 0.2, 5.0])
    assert agree(pixels(X))                          # in front: one point
    assert not agree(pixels(X * [1.0, 1.0, -1.0]))   # behind both: no point saw it
