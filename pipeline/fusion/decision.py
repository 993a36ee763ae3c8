"""The decision at the consensus limit: what a robot computes from the entries of its component
(Montijano et al., max-c consensus eqs. 6–7 and dynamic voting eqs. 10–14 at their limit).

Shared by the vectorized flood and by every :class:`~pipeline.fusion.flood_robot.FloodRobot`
(the exact mode of :mod:`pipeline.fusion.flooding`, whose docstring proves it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.fusion.consensus import solve_information

__all__ = ["Decision", "decide"]


@dataclass
class Decision:
    """What a robot computes from the entries of its component, per row (track and robot).

    Attributes
    ----------
    members : ndarray, (R, n, K) bool — ``V_h`` of eq. (7)
    yes : ndarray, (R, K, n) bool — ``Y_h``, the fixed point of ``F`` reached from ``V_h``
    counts : ndarray, (R, K) int — ``|Y_h|`` (the votes times ``N``)
    size : ndarray, (R,) int — ``N``, robots of the component
    winner : ndarray, (R,) int — most votes, ties to the lowest index
    theta : ndarray, (R, d) — ``θ_ML(Y_{h*})``; 0 where not ``valid``
    valid : ndarray, (R,) bool — ``Y_{h*}`` non-empty and its information matrix invertible
    cycles : ndarray, (R, K) bool — the iteration of ``F`` ended in a cycle
    """

    members: np.ndarray
    yes: np.ndarray
    counts: np.ndarray
    size: np.ndarray
    winner: np.ndarray
    theta: np.ndarray
    valid: np.ndarray
    cycles: np.ndarray


def _matvec(M, v):
    """``M v`` for (..., d, d) and (..., d), products summed in index order (row-independent)."""
    d = v.shape[-1]
    out = M[..., :, 0] * v[..., None, 0]
    for b in range(1, d):
        out = out + M[..., :, b] * v[..., None, b]
    return out


def _quadratic(r, M):
    """``r' M r`` for (..., d) and (..., d, d), summed in index order (row-independent)."""
    Mr = _matvec(M, r)
    out = r[..., 0] * Mr[..., 0]
    for a in range(1, r.shape[-1]):
        out = out + r[..., a] * Mr[..., a]
    return out


def decide(known, estimated, draws, x, info, *, c: int, thr: float,
           team: int | None = None) -> Decision:
    """The limit of max-c consensus and dynamic voting on the entries a robot holds.

    Parameters
    ----------
    known : ndarray, (R, n) bool — entries held (a robot's component once it closed it)
    estimated : ndarray, (R, n) bool — the robot formed an estimate (it votes and may be drawn)
    draws : ndarray, (R, n, K) — max-c draws (eq. 6)
    x : ndarray, (R, n, d) — observations (wire images)
    info : ndarray, (R, n, d, d) — ``Λ⁻¹`` (wire images)
    c : int — robots per hypothesis
    thr : float — gate on the squared Mahalanobis distance (eq. 12)
    team : int or None — robots of the team (default ``n``), for columns that hold only
        some of them in id order (a track's observers): it bounds the iterations of ``F``

    Returns
    -------
    Decision

    Notes
    -----
    Rows are independent: entries outside ``known`` are masked to zero before use, sums over
    robots run in id order. Cost ``O(R K n d² I)`` with ``I`` the iterations of ``F`` (a few).
    The iteration of ``F`` is capped at ``4 team + 4`` steps: a hypothesis that has reached
    neither a fixed point nor a cycle by then keeps its last set (``cycles`` false).
    """
    known = np.asarray(known, dtype=bool)
    R, n = known.shape
    obs = known & np.asarray(estimated, dtype=bool)
    dr = np.where(obs[..., None], np.asarray(draws, dtype=np.float64), -np.inf)  # (R, n, K)
    K = dr.shape[-1]
    d = x.shape[-1]
    # eq. (6)-(7) at the limit: the c largest distinct draws of the component
    s = -np.sort(-dr, axis=1)
    dup = np.zeros(s.shape, dtype=bool)
    dup[:, 1:] = s[:, 1:] == s[:, :-1]
    s = -np.sort(-np.where(dup, -np.inf, s), axis=1)
    cth = s[:, min(int(c), n) - 1] if int(c) <= n else np.full((R, K), -np.inf)
    members = np.isfinite(dr) & (dr >= cth[:, None, :])
    xm = np.where(obs[..., None], np.asarray(x, dtype=np.float64), 0.0)
    im = np.where(obs[..., None, None], np.asarray(info, dtype=np.float64), 0.0)
    qk = _matvec(im, xm)                                            # Λ⁻¹ x per robot
    eye = np.eye(d)

    def ml(S):
        """θ_ML of the robots in S (R, K, n): eq. (1), sums in robot order."""
        P = np.zeros(S.shape[:2] + (d, d))
        q = np.zeros(S.shape[:2] + (d,))
        for k in range(n):
            w = S[:, :, k]
            P = P + np.where(w[..., None, None], im[:, None, k], 0.0)
            q = q + np.where(w[..., None], qk[:, None, k], 0.0)
        empty = ~S.any(-1)
        theta, ok = solve_information(np.where(empty[..., None, None], eye, P), q)
        ok &= ~empty
        return np.where(ok[..., None], theta, 0.0), ok

    def gate(theta, ok):
        """F(S): the robots whose observation passes the gate of eq. (12) at θ."""
        r = xm[:, None] - theta[:, :, None]                          # (R, K, n, d)
        m2 = _quadratic(r, im[:, None])
        return ok[..., None] & obs[:, None] & (m2 <= thr)

    S = np.ascontiguousarray(members.transpose(0, 2, 1))            # (R, K, n)
    final = S.copy()
    finished = np.zeros((R, K), dtype=bool)
    cycles = np.zeros((R, K), dtype=bool)
    history = [S]
    for _ in range(4 * (n if team is None else int(team)) + 4):
        theta, ok = ml(S)
        nxt = gate(theta, ok)
        fixed = ~finished & (nxt == S).all(-1)
        final[fixed] = S[fixed]
        finished |= fixed
        for j, old in enumerate(history[:-1]):
            back = ~finished & (nxt == old).all(-1)
            if back.any():
                # a cycle S_j .. S_k: the set with the most robots, the earliest on ties
                loop = np.stack(history[j:], axis=0)[:, back]        # (L, m, n)
                pick = np.argmax(loop.sum(-1), axis=0)
                final[back] = loop[pick, np.arange(loop.shape[1])]
                cycles |= back
                finished |= back
        history.append(nxt)
        S = nxt
        if finished.all():
            break
    final[~finished] = S[~finished]
    counts = final.sum(-1)
    winner = np.argmax(counts, axis=-1)                             # ties: lowest index
    pick = final[np.arange(R), winner]
    theta, ok = ml(pick[:, None])
    return Decision(members=members, yes=final, counts=counts, size=known.sum(1),
                    winner=winner, theta=theta[:, 0], valid=ok[:, 0], cycles=cycles)
