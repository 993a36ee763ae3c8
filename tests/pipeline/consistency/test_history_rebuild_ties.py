"""The history repair's order (pipeline.consistency.history.rebuild): links of equal quality
are added by increasing id, so every robot of the set skips the same one."""

import numpy as np

from pipeline.consistency.history import rebuild


def test_of_two_equal_links_the_lower_id_goes_first():
    """Features 1 and 3 are robot 0's frames of step 5, 2 robot 1's: links 10 (1-2) and 11
    (2-3) of equal quality cannot both stay; 10 comes first, 11 is skipped, whatever the
    order they are given in."""
    groups = {1: {0: [(5, 5)]}, 2: {1: [(5, 5)]}, 3: {0: [(5, 5)]}}
    q = np.array([0.5, 0.5])
    assert rebuild(groups, np.array([10, 11]), np.array([1, 2]), np.array([2, 3]), q
                   ).tolist() == [11]
    assert rebuild(groups, np.array([11, 10]), np.array([2, 1]), np.array([3, 2]), q
                   ).tolist() == [11]
