"""triangulate_views reports the reprojection RMS and the covariance of the point it returns
(after its last Gauss–Newton step), for any number of steps, none included."""

import numpy as np
import pytest

from data_synth.formations import look_at
from pipeline.fusion.local import project, triangulate_views


def _views():
    K = np.array([[400.0, 0.0, 320.0], [0.0, 400.0, 240.0], [0.0, 0.0, 1.0]])
    Rs, ts = zip(*(look_at([x, 0.3 * x, 0.0], [0.0, 0.0, 4.0], up=(0.0, 1.0, 0.0))
                   for x in (-1.5, -0.5, 0.5, 1.5)), strict=True)
    return np.stack(Rs), np.stack(ts), np.broadcast_to(K, (4, 3, 3)).copy()


@pytest.mark.parametrize("iterations", [0, 1, 3])
def test_rms_and_covariance_are_those_of_the_returned_point(iterations):
    R, t, K = _views()
    X0 = np.array([0.2, -0.1, 4.0])
    u, _, _ = project(X0[None, None], R, t, K)
    uv = u + np.random.default_rng(0).normal(0.0, 4.0, u.shape)      # (1, 4, 2), 4 px noise
    X, cov, ok, rms = triangulate_views(uv, np.ones((1, 4), bool), R, t, K, sigma_px=2.0,
                                        iterations=iterations)
    assert ok.tolist() == [True]
    u_at, J, _ = project(X[:, None], R, t, K)
    want_rms = np.sqrt(((u_at - uv) ** 2).sum((1, 2)) / 4)
    np.testing.assert_allclose(rms, want_rms, rtol=1e-9, atol=0)
    H = np.einsum("mvij,mvik->mjk", J, J)
    np.testing.assert_allclose(cov, 4.0 * np.linalg.inv(H), rtol=1e-6, atol=0)
