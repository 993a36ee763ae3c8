"""Dynamic voting (Montijano et al., Sec. IV-B) against the paper's equations written out
robot by robot: eq. (10) and eq. (5) for the start, eq. (12) for the test, eqs. (13)–(14)
for the inputs and eq. (11) with Metropolis weights ``a_ij = 1 / (1 + max(deg_i, deg_j))``
for the update, in plain loops; every round's estimate, vote and opinion must agree."""

import numpy as np
import pytest
from scipy.stats import chi2

from pipeline.fusion.voting import choose_hypotheses, dynamic_voting

EDGES = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 0), (1, 4)]


def by_hand(x, cov, members, observed, thr, rounds):
    N, d = x.shape
    K = members.shape[1]
    nbrs = [[j for e in EDGES for j in e if i in e and j != i] for i in range(N)]
    deg = [len(nb) for nb in nbrs]
    info = [np.linalg.inv(c) for c in cov]
    P = [[info[i] * members[i, h] for h in range(K)] for i in range(N)]       # eq. (5)
    q = [[info[i] @ x[i] * members[i, h] for h in range(K)] for i in range(N)]
    v = [[float(members[i, h]) for h in range(K)] for i in range(N)]          # eq. (10)
    prev = [[bool(members[i, h]) for h in range(K)] for i in range(N)]
    thetas, yeses, votes = [], [], []
    for t in range(rounds + 1):
        theta = np.zeros((N, K, d))
        yes = np.zeros((N, K), bool)
        for i in range(N):
            for h in range(K):
                ev = np.linalg.eigvalsh(P[i][h])
                if ev[0] > 1e-10 * np.abs(ev).max():  # no vote while P_i is singular
                    theta[i, h] = np.linalg.solve(P[i][h], q[i][h])
                    r = x[i] - theta[i, h]
                    yes[i, h] = observed[i] and r @ info[i] @ r <= thr        # eq. (12)
        thetas.append(theta)
        yeses.append(yes)
        votes.append(np.array(v))
        if t == rounds:
            break
        newP, newq, newv = [], [], []
        for i in range(N):
            rowP, rowq, rowv = [], [], []
            for h in range(K):
                u = int(yes[i, h]) - int(prev[i][h])                          # eqs. (13)-(14)
                a = {j: 1.0 / (1 + max(deg[i], deg[j])) for j in nbrs[i]}
                a_ii = 1.0 - sum(a.values())
                rowP.append(a_ii * P[i][h] + sum(a[j] * P[j][h] for j in nbrs[i]) + u * info[i])
                rowq.append(a_ii * q[i][h] + sum(a[j] * q[j][h] for j in nbrs[i])
                            + u * info[i] @ x[i])
                rowv.append(a_ii * v[i][h] + sum(a[j] * v[j][h] for j in nbrs[i]) + u)
            newP.append(rowP)
            newq.append(rowq)
            newv.append(rowv)
        P, q, v = newP, newq, newv
        prev = [[bool(yes[i, h]) for h in range(K)] for i in range(N)]
    return np.array(thetas), np.array(yeses), np.array(votes)


@pytest.mark.parametrize("gate", ["squared", "distance"])
def test_every_round_of_dynamic_voting_follows_eqs_10_to_14(gate):
    rng = np.random.default_rng(3)
    N, d = 6, 2
    x = rng.normal(0, 0.4, (N, d))
    x[2] += [6.0, 0.0]                       # an outlier: opinions change on the way
    A = rng.normal(size=(N, d, d))
    cov = A @ np.swapaxes(A, 1, 2) * 0.5 + 0.3 * np.eye(d)
    members = np.zeros((N, 3), bool)
    members[0, 0] = members[2, 1] = True
    members[[3, 5], 2] = True
    observed = np.ones(N, bool)
    observed[4] = False                      # relays only
    q = chi2.ppf(0.9, d)
    thr = q * q if gate == "distance" else q
    rounds = 25
    theta, yes, v = by_hand(x, cov, members, observed, thr, rounds)
    res = dynamic_voting(x, cov, EDGES, K=3, p=0.9, gate=gate, rounds=rounds,
                         members=members[None], observed=observed, history=True)
    h = res.history
    np.testing.assert_array_equal(h["yes"][:, 0], yes)
    np.testing.assert_allclose(h["v"][:, 0], v, atol=1e-12)
    np.testing.assert_allclose(h["theta"][:, 0], theta, rtol=1e-9, atol=1e-9)
    # some opinion changes happened (the test exercises eqs. 13-14)
    assert (yes[1:] != yes[:-1]).any()
    # the final view: the winner is each robot's argmax of its votes, its gate the inlier flag
    # (votes within 1e-4 of the largest tie, the lowest index wins)
    winner = (v[-1] >= v[-1].max(1, keepdims=True) - 1e-4).argmax(1)
    np.testing.assert_array_equal(res.winner[0], winner)
    np.testing.assert_array_equal(res.inlier[0], yes[-1][np.arange(N), winner])


def test_only_observing_robots_are_drawn_into_hypotheses():
    observed = np.zeros((4, 6), bool)
    observed[0, [1, 4]] = True
    observed[1, :] = True
    observed[2, [0, 2, 3, 5]] = True
    observed[3, 2] = True                    # one observer: fewer than c draws
    for seed in range(20):
        members, _ = choose_hypotheses(observed, EDGES, K=4, c=2, rng=seed)
        assert not (members & ~observed[..., None]).any()
        # min(c, observers) members per hypothesis (a connected graph)
        np.testing.assert_array_equal(members.sum(1), [[2] * 4] * 3 + [[1] * 4])


def test_given_members_that_do_not_observe_are_dropped():
    x = np.zeros((6, 2))
    cov = np.broadcast_to(np.eye(2), (6, 2, 2))
    observed = np.ones((1, 6), bool)
    observed[0, 2] = False
    members = np.zeros((1, 6, 1), bool)
    members[0, [1, 2], 0] = True
    res = dynamic_voting(x, cov, EDGES, K=1, rounds=2, members=members, observed=observed[0])
    np.testing.assert_array_equal(res.members[0, :, 0], [0, 1, 0, 0, 0, 0])
