"""Local estimates: the ``pair`` mode takes the observing neighbour whose ray makes the
widest angle with the robot's own (rays in the world frame, ``Rᵀ K⁻¹ x``, by hand here), and
a robot's covariance scales with the square of its own keypoint noise, ``σ_i² (Σ JᵀJ)⁻¹``,
with ``J`` checked against central differences of the projection."""

import numpy as np

from pipeline.fusion.local import local_estimates, triangulate_views
from tests.pipeline.fusion.test_landmarks import project, rig


def _scene(B=40, n=4, seed=0):
    rng = np.random.default_rng(seed)
    R, t, K = rig(n)
    # turn the rig and the scene about the world's vertical and roll each camera about its
    # own axis: the world rays Rᵀ K⁻¹ x differ from R K⁻¹ x
    a = 0.6
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    for k in range(n):
        c = 0.25 * (k - 1.5)
        Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
        R[k] = Rz @ R[k] @ Ry.T
    X = rng.uniform([-1, -1, 4], [1, 1, 6], (B, 3)) @ Ry.T   # the scene turned with the rig
    kp = project(X[:, None], R[None], t[None], K[None]) + rng.normal(0, 0.5, (B, n, 2))
    observes = rng.random((B, n)) < 0.85
    adj = ~np.eye(n, dtype=bool)
    adj[0, 3] = adj[3, 0] = False
    return kp, observes, adj, R, t, K


def test_pair_mode_takes_the_widest_angle():
    kp, observes, adj, R, t, K = _scene()
    B, n = observes.shape
    X, cov, est = local_estimates(kp, observes, adj, R, t, K, 1.0, 9.21, "pair")
    checked = 0
    for b in range(B):
        for i in range(n):
            nbrs = [j for j in range(n) if j != i and adj[i, j] and observes[b, i]
                    and observes[b, j]]
            if not nbrs:
                assert not est[b, i]
                continue
            ray = {}
            for j in [i] + nbrs:
                r = R[j].T @ np.linalg.solve(K[j], np.r_[kp[b, j], 1.0])
                ray[j] = r / np.linalg.norm(r)
            partner = min(nbrs, key=lambda j: (ray[i] @ ray[j], j))
            two = np.array([i, partner])
            Xw, _, ok, _ = triangulate_views(kp[b, two][None], np.ones((1, 2), bool),
                                             R[two][None], t[two][None], K[two][None])
            assert est[b, i] == ok[0]
            np.testing.assert_allclose(X[b, i], Xw[0], rtol=1e-9, atol=1e-9)
            checked += 1
    assert checked > 20


def test_covariance_scales_with_the_square_of_each_robots_noise():
    kp, observes, adj, R, t, K = _scene(seed=1)
    sigma = np.array([1.0, 2.5, 0.5, 3.0])
    X1, cov1, est1 = local_estimates(kp, observes, adj, R, t, K, 1.0, 1e9, "neighbours")
    Xs, covs, ests = local_estimates(kp, observes, adj, R, t, K, sigma, 1e9, "neighbours")
    np.testing.assert_array_equal(ests, est1)
    np.testing.assert_array_equal(Xs, X1)
    np.testing.assert_allclose(covs[est1], (cov1 * sigma[None, :, None, None] ** 2)[est1],
                               rtol=1e-12)


def test_triangulation_covariance_is_the_inverse_normal_matrix_of_the_projection():
    R, t, K = rig(3)
    X = np.array([0.3, -0.2, 5.5])
    uv = np.stack([project(X, R[v], t[v], K[v]) for v in range(3)])
    Xs, cov, ok, _ = triangulate_views(uv[None], np.ones((1, 3), bool), R[None], t[None],
                                       K[None], sigma_px=2.0)
    h = 1e-6
    J = np.zeros((6, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        J[:, k] = np.concatenate([(project(X + e, R[v], t[v], K[v])
                                   - project(X - e, R[v], t[v], K[v])) / (2 * h)
                                  for v in range(3)])
    assert ok[0]
    np.testing.assert_allclose(cov[0], 4.0 * np.linalg.inv(J.T @ J), rtol=1e-5)
