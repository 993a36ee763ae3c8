"""decide (pipeline.fusion.decision): the limit of max-c consensus (eqs. 6-7) counts a draw
heard from two robots once, and the iteration of the gate runs until its fixed point however
many steps that takes."""

import numpy as np

from pipeline.fusion.decision import decide
from pipeline.fusion.voting import choose_hypotheses, gate_threshold

PATH4 = np.array([(0, 1), (1, 2), (2, 3)])


def test_members_are_those_of_max_c_consensus_when_two_robots_drew_one_value():
    # c = 2: the two largest distinct draws are 0.9 (robots 0 and 2) and 0.5 (robot 1)
    draws = np.array([[[0.9], [0.5], [0.9], [0.2]]])
    x = np.zeros((1, 4, 1))
    info = np.ones((1, 4, 1, 1))
    dec = decide(np.ones((1, 4), bool), np.ones((1, 4), bool), draws, x, info, c=2, thr=1.0)
    assert dec.members[0, :, 0].tolist() == [True, True, True, False]
    members, _ = choose_hypotheses(np.ones((1, 4), bool), PATH4, 1, 2, None, draws=draws)
    np.testing.assert_array_equal(dec.members, members)


def test_the_gate_is_iterated_to_its_fixed_point():
    # 1-D, Λ_i = 1, gate radius r: robots at 0, 0.9 r, 0.9 r √2, 0.9 r √3, ...; the hypothesis
    # of robot 0 takes one more robot at each step of F (the ML moves towards the chain) and
    # loses robot 0 at the seventh: {1, ..., 7} is the fixed point
    thr = gate_threshold(1, 0.99, "squared")
    r = np.sqrt(thr)
    n = 8
    x = (0.9 * r * np.sqrt(np.arange(n)))[None, :, None]
    draws = np.linspace(1.0, 0.1, n)[None, :, None]                 # robot 0 drew the largest
    dec = decide(np.ones((1, n), bool), np.ones((1, n), bool), draws, x, np.ones((1, n, 1, 1)),
                 c=1, thr=thr)
    S = dec.yes[0, 0]
    assert S.tolist() == [False] + [True] * (n - 1)
    # a fixed point: the gate at the ML of S admits exactly S
    theta = x[0, S, 0].mean()
    np.testing.assert_array_equal((x[0, :, 0] - theta) ** 2 <= thr, S)
    np.testing.assert_allclose(dec.theta[0, 0], theta, rtol=1e-12)
