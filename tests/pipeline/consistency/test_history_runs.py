"""Step runs of retired frames (pipeline.consistency.history): the groups in which one robot
holds two overlapping runs, against a brute-force count."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.consistency.history import overlapping_runs


def test_a_long_run_of_one_group_does_not_reach_into_the_next():
    """Group 0: robot 0's steps 0-10; group 1: its steps 0-1 and 5-6, apart."""
    out = overlapping_runs(np.array([0, 1, 1]), np.array([0, 0, 0]), np.array([0, 0, 5]),
                           np.array([10, 1, 6]))
    assert out == []


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(0, 2), st.integers(0, 12),
                          st.integers(0, 4)), max_size=14))
def test_overlapping_runs_are_those_of_a_brute_force_count(rows):
    group = np.array([r[0] for r in rows], np.int64)
    robot = np.array([r[1] for r in rows], np.int64)
    lo = np.array([r[2] for r in rows], np.int64)
    hi = lo + np.array([r[3] for r in rows], np.int64)
    want = sorted({int(group[i]) for i in range(len(rows)) for j in range(i + 1, len(rows))
                   if group[i] == group[j] and robot[i] == robot[j]
                   and lo[i] <= hi[j] and lo[j] <= hi[i]})
    assert overlapping_runs(group, robot, lo, hi) == want
