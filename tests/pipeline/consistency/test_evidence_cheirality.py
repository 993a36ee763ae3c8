"""The one-point test of the evidence rule refuses points behind a camera: the three-view DLT
point (:func:`one_point`) and the point at infinity (:func:`far_point`) alike; a distant
point is still a point."""

import numpy as np

from pipeline.consistency.evidence import (
    REPROJECTION_TOL_PX,
    far_point,
    one_point,
    triangle_support,
)

F, CX, CY = 500.0, 320.0, 240.0
K = np.array([[F, 0.0, CX], [0.0, F, CY], [0.0, 0.0, 1.0]])


def camera(R, centre) -> np.ndarray:
    R = np.asarray(R, dtype=np.float64)
    return K @ np.c_[R, -R @ np.asarray(centre, dtype=np.float64)]


def project(P, X) -> np.ndarray:
    p = P @ np.r_[X, 1.0]
    return p[:2] / p[2]


FORWARD = np.eye(3)                      # looking along +z
BACKWARD = np.diag([1.0, -1.0, -1.0])    # looking along -z


def test_rays_that_meet_behind_the_cameras_are_not_one_point():
    # three cameras looking along +z; the point (0.3, 0.2, -5) lies behind all three. Its
    # pixels satisfy the projection equations exactly (the DLT finds it), but no camera saw it.
    Ps = [camera(FORWARD, c) for c in ((0, 0, 0), (1, 0, 0), (0, 1, 0))]
    X = np.array([0.3, 0.2, -5.0])
    kp = np.array([[project(P, X) for P in Ps]])
    assert one_point(kp, np.array([Ps]), REPROJECTION_TOL_PX).tolist() == [False]
    # the same pixels of a point in front of them: one point
    front = np.array([[project(P, -X) for P in Ps]])
    assert one_point(front, np.array([Ps]), REPROJECTION_TOL_PX).tolist() == [True]
    # hence no triangle support for the three links between them
    keypoints = {g: kp[0, g] for g in range(3)}
    projections = dict(enumerate(Ps))
    support = triangle_support(np.array([0, 0, 1]), np.array([1, 2, 2]), lambda g: np.asarray(g),
                               keypoints, projections)
    assert support.tolist() == [0, 0, 0]


def test_a_direction_behind_one_camera_is_not_a_far_point():
    # cameras A (origin) and C (x = 1) look along +z at their image centres; camera B, at
    # z = -10, looks along -z at its centre. The mean ray is +z: in front of A and C, behind B
    # (whose centre pixel is also where +z projects, with negative depth).
    Ps = [camera(FORWARD, (0, 0, 0)), camera(BACKWARD, (0, 0, -10)), camera(FORWARD, (1, 0, 0))]
    kp = np.array([[[CX, CY]] * 3])
    assert far_point(kp, np.array([Ps]), REPROJECTION_TOL_PX).tolist() == [False]
    # B turned to look along +z as well: the three rays meet at infinity, in front of all
    Ps[1] = camera(FORWARD, (0, 0, -10))
    assert far_point(kp, np.array([Ps]), REPROJECTION_TOL_PX).tolist() == [True]


def test_a_distant_point_seen_with_parallax_is_one_point():
    # three cameras 100 apart see a point 2000 away: its homogeneous coordinate is about
    # 5e-4 of the DLT vector, still a finite point; its rays spread over 0.05 rad (12 px at
    # f = 500), so the point at infinity would not fit them, the point itself does
    Ps = [camera(FORWARD, c) for c in ((0, 0, 0), (100, 0, 0), (0, 100, 0))]
    X = np.array([30.0, 20.0, 2000.0])
    kp = np.array([[project(P, X) for P in Ps]])
    assert far_point(kp, np.array([Ps]), REPROJECTION_TOL_PX).tolist() == [False]
    assert one_point(kp, np.array([Ps]), REPROJECTION_TOL_PX).tolist() == [True]
