import numpy as np

from pipeline.fusion.points import fused_points


def test_ties_go_to_the_lowest_robot_group_and_the_lowest_hypothesis():
    """Module docstring: groups {0, 1} and {2, 3} are equally large, and robots 0 and 1 picked
    hypotheses 1 and 0: the point is robot 1's (lowest robot's group, lowest hypothesis)."""
    theta = np.arange(12.0).reshape(1, 4, 3)
    f = fused_points(np.array([[0, 1], [2, 3]]), np.ones((1, 4), bool), theta,
                     np.array([[1, 0, 0, 0]]), 2)
    assert f.group.tolist() == [[False, True, False, False]]
    np.testing.assert_array_equal(f.points, theta[:, 1])
    assert f.split.tolist() == [True]
