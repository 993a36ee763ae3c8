"""``Λ⁻¹`` as the fusion messages carry it: exactly symmetric (a message sends the upper
triangle of ``P``, which is all of it only if ``P`` is), and the inverse to round-off."""

import numpy as np

from pipeline.fusion.voting import information_matrix


def test_information_matrix_is_exactly_symmetric_and_the_inverse():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(500, 3, 3))
    cov = A @ np.swapaxes(A, -1, -2) + 0.05 * np.eye(3)
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    info = information_matrix(cov)
    np.testing.assert_array_equal(info, np.swapaxes(info, -1, -2))
    np.testing.assert_allclose(info @ cov, np.broadcast_to(np.eye(3), cov.shape), atol=1e-8)
