"""Each robot's keypoint noise measured from its own tracks (pipeline.fusion.noise)."""

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.fusion.local import local_estimates
from pipeline.fusion.noise import MIN_RESIDUALS, gate_scale, robot_noise, two_view_residuals
from tests.pipeline.fusion.test_landmarks import project, rig


def _tracks(n=5, B=300, noise=(2.0, 2.0, 2.0, 2.0, 2.0), seed=3, observe=0.8):
    """``B`` points seen by ``n`` cameras, each camera's keypoints with its own Gaussian
    noise (standard deviation per coordinate, pixels)."""
    rng = np.random.default_rng(seed)
    R, t, K = rig(n)
    X = rng.uniform([-1, -1, 4], [1, 1, 6], (B, 3))
    kp = project(X[:, None], R[None], t[None], K[None])
    kp = kp + rng.normal(0, 1, (B, n, 2)) * np.asarray(noise, float)[None, :, None]
    observes = rng.random((B, n)) < observe
    adj = ~np.eye(n, dtype=bool)
    return kp, observes, adj, R, t, K


def test_the_two_view_residual_is_one_gaussian_degree_of_freedom():
    # d = distance of the keypoint pair to the pairs the poses allow: |N(0, σ²)| to first
    # order, so median(d) / 0.6745 recovers σ
    kp, observes, adj, R, t, K = _tracks(B=2000)
    nb = observes[:, :, None] & observes[:, None, :] & adj[None]
    _, lo, hi, d, ok = two_view_residuals(kp, nb, R, t, K)
    assert ok.mean() > 0.99 and (lo < hi).all()
    assert np.median(d[ok]) / 0.6745 == pytest.approx(2.0, rel=0.05)


def test_each_robot_measures_its_own_noise_above_the_floor():
    # cameras 3 and 4 are noisier: their residuals (with any partner) are larger
    kp, observes, adj, R, t, K = _tracks(noise=(0.5, 0.5, 0.5, 4.0, 4.0))
    sigma, count = robot_noise(kp, observes, adj, R, t, K, sigma_px=1.0, p=0.99)
    assert (count >= MIN_RESIDUALS).all()
    assert sigma[3:].min() > 2 * sigma[:3].max()
    assert (sigma >= 1.0).all()
    # the scale: the Gaussian whose 99 % quantile of d is the fitted exponential law's
    nb = observes[:, :, None] & observes[:, None, :] & adj[None]
    _, lo, hi, d, ok = two_view_residuals(kp, nb, R, t, K)
    mine = ok & ((lo == 4) | (hi == 4))
    assert sigma[4] == pytest.approx(gate_scale(np.median(d[mine]), 0.99), rel=1e-12)
    assert gate_scale(1.0, 0.99) == pytest.approx(np.log(100) / (np.log(2) * 2.5758293), rel=1e-6)


def test_clean_keypoints_keep_the_floor_and_fixed_mode_is_the_floor():
    kp, observes, adj, R, t, K = _tracks(noise=(0.05,) * 5)
    sigma, _ = robot_noise(kp, observes, adj, R, t, K, sigma_px=1.0)
    assert (sigma == 1.0).all()
    noisy = _tracks()
    sigma, count = robot_noise(*noisy, sigma_px=1.5, noise="fixed")
    assert (sigma == 1.5).all() and (count == 0).all()
    with pytest.raises(InputError):
        robot_noise(*noisy, noise="guessed")


def test_a_robot_with_too_few_residuals_keeps_the_floor():
    kp, observes, adj, R, t, K = _tracks(B=3, observe=1.0, noise=(5.0,) * 5)
    adj[:] = False
    adj[0, 1] = adj[1, 0] = True          # robots 0 and 1 share 3 tracks: 3 residuals each
    sigma, count = robot_noise(kp, observes, adj, R, t, K)
    assert count.tolist() == [3, 3, 0, 0, 0]
    assert (sigma == 1.0).all()


def test_a_robot_alone_measures_what_the_simulator_measures():
    kp, observes, adj, R, t, K = _tracks(noise=(0.5, 3.0, 1.0, 4.0, 2.5), B=120)
    adj[0, 4] = adj[4, 0] = False
    sigma, count = robot_noise(kp, observes, adj, R, t, K)
    X, cov, est = local_estimates(kp, observes, adj, R, t, K, sigma, 9.21)
    for i in range(len(sigma)):
        own = np.arange(len(sigma)) == i
        s_i, c_i = robot_noise(kp, observes, adj, R, t, K, robots=own)
        assert s_i[i] == sigma[i] and c_i[i] == count[i]
        X_i, cov_i, est_i = local_estimates(kp, observes, adj, R, t, K, s_i, 9.21, robots=own)
        np.testing.assert_array_equal(est[:, i], est_i[:, i])
        np.testing.assert_array_equal(X[:, i], X_i[:, i])
        np.testing.assert_array_equal(cov[:, i], cov_i[:, i])
