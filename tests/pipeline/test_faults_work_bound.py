"""The simulated-work bound at its edge: one detection on a faulty path of ``n`` robots takes
``(D + 1)(d + 3)`` rounds with ``d = n - 1`` (pipeline.faults, "Time")."""

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.faults import MAX_ROBOT_ROUNDS, FaultConfig, check_simulated_work


def _path(n):
    return np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)


def test_a_path_just_over_the_bound_is_refused_and_one_robot_fewer_runs():
    faults = FaultConfig(delay_rounds=100)
    # 140 robots: 140 * 101 * (139 + 3) = 2,007,880 robot-rounds; 139: 1,979,499
    assert 139 * 101 * 141 <= MAX_ROBOT_ROUNDS < 140 * 101 * 142
    with pytest.raises(InputError, match=r"\(D \+ 1\)\(d \+ 3\) = 14342 rounds"):
        check_simulated_work(140, _path(140), faults)
    check_simulated_work(139, _path(139), faults)
