"""Known-pose evidence on a general two-camera geometry: rotation, translation off the axes
and different intrinsics, where ``F`` is neither symmetric nor antisymmetric, so taking the
two cameras in the wrong order shows."""

import numpy as np

from pipeline.matching.link_evidence import edge_evidence, link_evidence
from pipeline.types import Features, Links, PairMatches, View


def test_pose_error_of_exact_correspondences_is_zero_for_a_general_pose():
    rng = np.random.default_rng(0)
    K0 = np.array([[400.0, 0, 320], [0, 410.0, 240], [0, 0, 1]])
    K1 = np.array([[600.0, 0, 300], [0, 590.0, 200], [0, 0, 1]])
    a = 0.3
    R1 = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    t1 = np.array([-1.0, 0.3, 0.2])
    b = -0.2
    R0 = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    t0 = np.array([0.4, -0.1, 0.3])
    X = np.c_[rng.uniform(-1, 1, (6, 2)), rng.uniform(4, 6, 6)]

    def proj(K, R, t):
        p = (K @ (R @ X.T + t[:, None])).T
        return (p[:, :2] / p[:, 2:]).astype(np.float32)

    order = np.array([3, 0, 5, 1, 4, 2])  # camera 1 holds point k as its feature order[k]
    kp = [proj(K0, R0, t0), np.empty((6, 2), np.float32)]
    kp[1][order] = proj(K1, R1, t1)
    kp[1][order[5]] += [0.0, 4.0]  # point 5 moved 4 px in camera 1
    feats = [Features(k, np.zeros((6, 8), np.float32), np.ones(6, np.float32), "sift")
             for k in kp]
    views = [View("a", np.zeros((4, 4)), K0, R0, t0), View("b", np.zeros((4, 4)), K1, R1, t1)]
    pm = PairMatches(0, 1, np.stack([np.arange(6), order], 1).astype(np.int32),
                     np.full(6, 0.3, np.float32), np.full(6, 0.2, np.float32))
    ev = link_evidence([pm], Links.from_matches([pm]), views, feats)
    assert ev.pose_error[:5].max() < 1e-2
    assert ev.pose_error[5] > 1.0
    one = edge_evidence(pm, kp[0], kp[1], (K0, R0, t0), (K1, R1, t1))
    np.testing.assert_array_equal(one.pose_error, ev.pose_error)
