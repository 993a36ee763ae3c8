"""A covariance with a zero eigenvalue is no covariance of an observation (its inverse, the
information the consensus adds, does not exist): refused with the robot named, like a
negative one."""

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.fusion.voting import distributed_ml, dynamic_voting


@pytest.mark.parametrize("bad", [np.diag([1.0, 0.0]), np.zeros((2, 2))])
def test_a_singular_covariance_is_named(bad):
    x = np.array([[0.0, 0], [0.1, 0], [0, 0.1], [5, 5]])
    cov = np.broadcast_to(np.eye(2), (4, 2, 2)).copy()
    cov[2] = bad
    edges = np.array([[0, 1], [1, 2], [2, 3]])
    with pytest.raises(InputError, match="robot 2.*not positive definite"):
        dynamic_voting(x, cov, edges, K=1, rounds=1, rng=0)
    with pytest.raises(InputError, match="robot 2"):
        distributed_ml(x, cov, edges)
