"""The decision at the consensus limit against the definitions written out per row in plain
loops: ``V_h`` = the robots holding one of the ``c`` largest distinct draws of the component
(eqs. 6–7; never a robot without an estimate), ``Y_h`` = the fixed point of ``F(S)`` = the
robots whose observation passes the gate at ``θ_ML(S)`` (eqs. 12–13; no robot passes at an
empty or singular ``S``), the winner with most votes (ties: lowest index) and its ML."""

import numpy as np
import pytest

from pipeline.fusion.decision import decide


def by_hand(known, estimated, draws, x, info, c, thr):
    n, K = draws.shape
    obs = [bool(known[i] and estimated[i]) for i in range(n)]
    members = np.zeros((n, K), bool)
    yes = np.zeros((K, n), bool)
    for h in range(K):
        values = sorted({draws[i, h] for i in range(n) if obs[i]}, reverse=True)[:c]
        for i in range(n):  # (fewer than c distinct draws: all of them)
            members[i, h] = obs[i] and draws[i, h] in values

        def ml(S):
            if not any(S):
                return None
            P = sum(info[i] for i in range(n) if S[i])
            if np.linalg.eigvalsh(P)[0] <= 1e-10 * np.abs(np.linalg.eigvalsh(P)).max():
                return None
            return np.linalg.solve(P, sum(info[i] @ x[i] for i in range(n) if S[i]))

        S = tuple(members[:, h])
        seen = [S]
        while True:
            th = ml(S)
            nxt = tuple(obs[i] and th is not None
                        and (x[i] - th) @ info[i] @ (x[i] - th) <= thr for i in range(n))
            if nxt == S:
                break
            assert nxt not in seen, "a cycle: not drawn in these cases"
            seen.append(nxt)
            S = nxt
        yes[h] = S
    counts = yes.sum(1)
    winner = int(np.argmax(counts))
    th = ml(tuple(yes[winner]))
    return members, yes, counts, winner, th


@pytest.mark.parametrize("c", [1, 2, 3])
def test_decide_equals_the_definitions_row_by_row(c):
    rng = np.random.default_rng(c)
    R, n, K, d = 40, 5, 3, 2
    known = rng.random((R, n)) < 0.85
    estimated = rng.random((R, n)) < 0.8
    draws = rng.integers(1, 6, (R, n, K)) / 6.0        # repeated values: distinct draws count
    x = rng.normal(0, 1.0, (R, n, d))
    x[rng.random((R, n)) < 0.25] += [5.0, 0.0]        # outliers
    A = rng.normal(size=(R, n, d, d))
    info = np.linalg.inv(A @ np.swapaxes(A, -1, -2) * 0.3 + 0.5 * np.eye(d))
    info = 0.5 * (info + np.swapaxes(info, -1, -2))
    dec = decide(known, estimated, draws, x, info, c=c, thr=5.99)
    for b in range(R):
        members, yes, counts, winner, th = by_hand(known[b], estimated[b], draws[b], x[b],
                                                   info[b], c, 5.99)
        np.testing.assert_array_equal(dec.members[b], members)
        np.testing.assert_array_equal(dec.yes[b], yes)
        np.testing.assert_array_equal(dec.counts[b], counts)
        assert dec.winner[b] == winner and dec.size[b] == known[b].sum()
        assert dec.valid[b] == (th is not None)
        if th is not None:
            np.testing.assert_allclose(dec.theta[b], th, rtol=1e-9, atol=1e-12)
        else:
            assert not dec.theta[b].any()
