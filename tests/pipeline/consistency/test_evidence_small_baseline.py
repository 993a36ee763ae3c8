"""The evidence rule's geometric test on frames of a robot creeping (centres millimetres
apart, ``run-formation --steps --speed 1e-3``): observations of one point, with the keypoints'
noise, are one point. The DLT point alone landed anywhere on the nearly parallel rays (behind
a camera, or where it reprojects far off) and the rule cut good links; the rays agree, so the
point at infinity fits (pipeline.consistency.evidence.far_point)."""

import math

import numpy as np
import pytest

from pipeline.consistency.evidence import REPROJECTION_TOL_PX, evidence_cut, one_point

K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])


def _camera(yaw: float, centre) -> np.ndarray:
    R = np.array([[math.cos(yaw), 0, math.sin(yaw)], [0, 1, 0],
                  [-math.sin(yaw), 0, math.cos(yaw)]])
    return K @ np.c_[R, -R @ np.asarray(centre, dtype=np.float64)]


def _observe(P, X, rng, noise_px):
    p = P @ np.r_[X, 1.0]
    return p[:2] / p[2] + rng.normal(0.0, noise_px, 2)


@pytest.mark.parametrize("baseline_m", [1e-6, 1e-4, 1e-3])
def test_a_creeping_robots_frames_keep_their_matches(baseline_m):
    rng = np.random.default_rng(7)
    kept = 0
    for _ in range(50):
        X = rng.uniform([-3, -2, 8], [3, 2, 15])
        Ps = [_camera(0.05, [0.0, 0.0, 0.0]), _camera(0.05, [baseline_m, 0.0, 0.0]),
              _camera(0.05, [2 * baseline_m, 0.0, 0.0])]
        kp = np.array([_observe(P, X, rng, 0.5) for P in Ps])
        assert one_point(kp[None], np.array(Ps)[None], REPROJECTION_TOL_PX).tolist() == [True]
        cut = evidence_cut([0], [1], [0], [1], [1.0], {0: kp[0], 1: kp[1]},
                           {0: Ps[0], 1: Ps[1]})
        kept += int(not cut[0])
    assert kept == 50


def test_a_creeping_robots_wrong_match_is_still_refuted():
    """20 px apart through nearly one pose is no point, finite or at infinity."""
    Ps = [_camera(0.05, [0.0, 0.0, 0.0]), _camera(0.05, [1e-3, 0.0, 0.0])]
    kp = {0: np.array([300.0, 200.0]), 1: np.array([320.0, 200.0])}
    assert evidence_cut([0], [1], [0], [1], [1.0], kp, {0: Ps[0], 1: Ps[1]}).tolist() == [True]
