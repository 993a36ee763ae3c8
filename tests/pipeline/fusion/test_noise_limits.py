"""The limits of the noise measurement: exactly ``MIN_RESIDUALS`` residuals are enough, the
median is numpy's, and robots not asked for are not measured."""

import numpy as np

from pipeline.fusion.noise import MIN_RESIDUALS, gate_scale, robot_noise, two_view_residuals
from tests.pipeline.fusion.test_noise import _tracks


def test_exactly_min_residuals_measure_the_noise():
    kp, observes, adj, R, t, K = _tracks(B=MIN_RESIDUALS, observe=1.0, noise=(5.0,) * 5)
    adj[:] = False
    adj[0, 1] = adj[1, 0] = True          # robots 0 and 1 share 5 tracks: 5 residuals each
    sigma, count = robot_noise(kp, observes, adj, R, t, K, sigma_px=0.01, p=0.99)
    assert count.tolist() == [MIN_RESIDUALS, MIN_RESIDUALS, 0, 0, 0]
    nb = observes[:, :, None] & observes[:, None, :] & adj[None]
    _, _, _, d, ok = two_view_residuals(kp, nb, R, t, K)
    assert ok.all() and len(d) == MIN_RESIDUALS
    want = gate_scale(np.median(d), 0.99)
    np.testing.assert_allclose(sigma[:2], [want, want], rtol=1e-12)
    assert (sigma[2:] == 0.01).all()


def test_only_the_robots_asked_for_are_measured():
    kp, observes, adj, R, t, K = _tracks(B=60, noise=(3.0,) * 5)
    everyone, count_all = robot_noise(kp, observes, adj, R, t, K)
    mine = np.array([True, False, False, True, False])
    sigma, count = robot_noise(kp, observes, adj, R, t, K, robots=mine)
    np.testing.assert_array_equal(count[~mine], 0)
    np.testing.assert_array_equal(sigma[~mine], 1.0)
    np.testing.assert_array_equal(sigma[mine], everyone[mine])
    np.testing.assert_array_equal(count[mine], count_all[mine])
    assert (everyone[~mine] > 1.0).all()
