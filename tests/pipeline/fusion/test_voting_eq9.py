"""Static voting's votes (eq. 8) with the covariance of eq. (9), on a case solved by hand."""

import numpy as np

from pipeline.fusion.voting import dynamic_voting, gate_threshold, static_voting

#: three robots, every pair linked: Metropolis weights 1/3 everywhere, exact averages
TRIANGLE = np.array([(0, 1), (1, 2), (0, 2)])
P = 0.9


def test_members_and_others_vote_with_the_covariance_of_eq9():
    # Λ_i = I for all; V_h = {0, 1}. Eq. (4): θ_ML = (x_0 + x_1) / 2, Λ_ML = (Σ_V Λ_j⁻¹)⁻¹
    # = I / 2. Eq. (9): a member tests x_i - θ_ML against Λ_ML + Λ_i - 2 Λ_ML Λ_i⁻¹ Λ_ML = I,
    # the third robot against Λ_ML + Λ_i = 3 I / 2.
    thr = gate_threshold(2, P, "squared")
    a = np.sqrt(1.1 * thr)   # members: squared distance a² = 1.1 thr against I -> no
    b = np.sqrt(1.2 * thr)   # the third robot: b² / 1.5 = 0.8 thr -> yes
    x = np.array([[a, 0.0], [-a, 0.0], [b, 0.0]])
    cov = np.broadcast_to(np.eye(2), (3, 2, 2)).copy()
    members = np.array([[True], [True], [False]])
    res = static_voting(x, cov, TRIANGLE, K=1, c=2, p=P, gate="squared", rounds=(20, 0, 20),
                        members=members)
    # no averaging rounds: each robot's vote is its own eq. (8)
    assert res.votes[0, :, 0].tolist() == [0.0, 0.0, 1.0]
    # nearer, the members pass: a² = 0.9 thr
    x[:2, 0] = np.sqrt(0.9 * thr) * np.array([1.0, -1.0])
    x[2, 0] = np.sqrt(1.6 * thr)  # and the third robot fails: 1.6 thr / 1.5 > thr
    res = static_voting(x, cov, TRIANGLE, K=1, c=2, p=P, gate="squared", rounds=(20, 0, 20),
                        members=members)
    assert res.votes[0, :, 0].tolist() == [1.0, 1.0, 0.0]


def test_a_lone_member_votes_yes_where_eq9_gives_the_zero_matrix():
    # c = 1: θ_ML = x_i and Λ_ML = Λ_i, so eq. (9) is 0 for the member: it votes yes; the
    # others test their distance against 2 Λ_i
    thr = gate_threshold(2, P, "squared")
    x = np.array([[0.0, 0.0], [np.sqrt(1.8 * thr), 0.0], [np.sqrt(2.2 * thr), 0.0]])
    cov = np.broadcast_to(np.eye(2), (3, 2, 2)).copy()
    members = np.array([[True], [False], [False]])
    res = static_voting(x, cov, TRIANGLE, K=1, c=1, p=P, gate="squared", rounds=(20, 0, 20),
                        members=members)
    assert res.votes[0, :, 0].tolist() == [1.0, 1.0, 0.0]


def test_a_small_eq9_covariance_is_used_not_taken_for_round_off():
    # member 0 is 10⁴ times more precise than member 1 (Λ_0 = 1e-4 I, Λ_1 = I): θ_ML lies
    # near x_0 and eq. (9) for member 0 is about 3e-8 I, 1.5e-4 of Λ_0's trace, far above
    # round-off; against it the residual 1e-4 (x_1 - x_0) has squared distance about
    # |x_1 - x_0|² / 3. Member 1 tests against about Λ_1 - 1e-4 I (its residual ≈ x_1 - x_0).
    thr = gate_threshold(2, P, "squared")
    eps = 1e-4
    x = np.array([[0.0, 0.0], [np.sqrt(3.6 * thr), 0.0], [0.0, 0.0]])
    cov = np.stack([eps * np.eye(2), np.eye(2), np.eye(2)])
    members = np.array([[True], [True], [False]])
    res = static_voting(x, cov, TRIANGLE, K=1, c=2, p=P, gate="squared", rounds=(20, 0, 20),
                        members=members)
    assert res.votes[0, :, 0].tolist() == [0.0, 0.0, 1.0]


def test_a_robot_that_does_not_observe_never_votes_in_dynamic_voting():
    # four robots, every pair linked; robot 3 holds no observation of the landmark. The three
    # observations lie around the origin, where robot 3's (unused) entry is stored as zero:
    # eq. (12) is a test of an observation, so robot 3 never votes and never joins the ML.
    square = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
    x = np.array([[0.1, 0.0], [-0.1, 0.0], [0.0, 0.1], [123.0, -7.0]])
    cov = np.broadcast_to(np.eye(2), (4, 2, 2)).copy()
    observed = np.array([True, True, True, False])
    members = np.array([[True], [True], [True], [False]])
    res = dynamic_voting(x, cov, square, K=1, p=P, gate="squared", rounds=60,
                         members=members, observed=observed)
    assert res.inlier[0].tolist() == [True, True, True, False]
    np.testing.assert_allclose(res.votes[0, :, 0], 0.75, atol=1e-9)
    np.testing.assert_allclose(res.theta[0, :3], np.tile(x[:3].mean(0), (3, 1)), atol=1e-9)
