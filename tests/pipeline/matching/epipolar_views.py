"""Shared by the landmark matching tests of this folder: two views of 3D points with a real
epipolar geometry."""

import numpy as np


def project_two(X: np.ndarray, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of the points ``X`` (N, 3) in two cameras of the same ``K``: the first at the
    origin, the second rotated by ``angle`` about the vertical axis and moved."""
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    R = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                  [-np.sin(angle), 0, np.cos(angle)]])
    t = np.array([-1.0, 0.1, 0.2])

    def project(P):
        p = P @ K.T
        return p[:, :2] / p[:, 2:]

    return project(X), project(X @ R.T + t)
