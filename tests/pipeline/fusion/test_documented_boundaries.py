"""The boundaries the fusion helpers document, at values that floating point holds exactly."""

import numpy as np

from pipeline.fusion.consensus import solve_information
from pipeline.fusion.voting import pick_winner


def test_a_vote_exactly_tie_tol_below_the_largest_is_tied():
    # "votes within tie_tol of the largest are tied and the lowest index among them wins"
    assert pick_winner(np.array([0.5, 0.75]), 0.25).tolist() == 0
    assert pick_winner(np.array([0.5, 0.875]), 0.25).tolist() == 1


def test_smallest_eigenvalue_exactly_rtol_times_the_largest_is_singular():
    # "P counts as singular when its smallest eigenvalue is <= rtol times its largest"
    P = np.diag([0.25, 1.0])[None]
    theta, ok = solve_information(P, np.ones((1, 2)), rtol=0.25)
    assert ok.tolist() == [False] and theta.tolist() == [[0.0, 0.0]]
    theta, ok = solve_information(P, np.ones((1, 2)), rtol=0.125)
    assert ok.tolist() == [True]
    np.testing.assert_allclose(theta, [[4.0, 1.0]], rtol=1e-12)
