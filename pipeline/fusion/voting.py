"""Robust distributed fusion by voting (Montijano, Martínez, Sagüés, Secs. II–IV).

Three estimators of an attribute ``θ ∈ R^d`` observed by ``N`` robots, each with a
measurement ``x_i`` and covariance ``Λ_i``; all run on the consensus blocks of
:mod:`pipeline.fusion.consensus` (neighbour-only messages, counted) and are vectorized over
hypotheses and over many independent problems (trials or landmarks) at once:

* :func:`distributed_ml` — the non-robust ML of all observations (eqs. 1–3);
* :func:`static_voting` — Sec. IV-A: hypotheses by max-c consensus (eqs. 6–7) and ML
  consensus on the chosen subsets (eqs. 4–5), chi-square votes (eq. 8) with the covariance
  of eq. (9), average consensus of the votes, winner ``h* = argmax_h v_i^h``, final ML of the
  robots that voted for ``h*``;
* :func:`dynamic_voting` — Sec. IV-B: hypotheses and votes in one consensus, eqs. (10)–(14);
  a robot re-tests its observation against its current estimate every round and adds or
  withdraws its ``(Λ_i⁻¹, Λ_i⁻¹ x_i, 1)`` when its opinion changes.

Shapes: ``B`` problems, ``N`` robots per problem, ``K`` hypotheses, ``d`` dimensions. Flat
node ``b * N + i`` is robot ``i`` of problem ``b`` (see the consensus module).

Readings of the text (where the paper leaves a choice open)
-----------------------------------------------------------
* **The chi-square gate** (eqs. 8, 12, 13). The paper calls ``d`` the Mahalanobis
  *distance* (after eq. 8) and writes it with a square root (Sec. IV-C, ``d_i(w)`` before
  Condition 4; eq. 17 differentiates that form), and eqs. (8) and (13) compare it with the
  chi-square *quantile* ``χ²_{d,p}``. ``gate="distance"`` follows that literally
  (``sqrt(r' Λ⁻¹ r) <= χ²_{d,p}``); ``gate="squared"`` is the usual chi-square test
  (``r' Λ⁻¹ r <= χ²_{d,p}``). ``p`` is not given in the paper.
* **Singular P** (Sec. IV-B, after eq. 12): a robot whose ``P_i(t)`` is singular votes no.
  The paper says so only where ``P_i⁻¹(t)`` does not exist; an indefinite ``P_i``, which
  eq. (14) can create transiently when a robot withdraws, is invertible, but its
  ``θ_i = P_i⁻¹ q_i`` is no combination of observations with weights in ``[0, 1]`` (the ``w``
  of Sec. IV-C), so it is treated the same way
  (:func:`pipeline.fusion.consensus.solve_information`).
* **Eq. (9) for a member of a one-robot hypothesis** (``c = 1``): then ``θ_ML^h = x_i`` and
  ``Λ_ML^h = Λ_i``, so eq. (9) gives the zero matrix — the residual ``x_i − θ_ML^h`` is
  exactly zero. A member whose eq.-(9) covariance is not positive definite votes yes.
* **Λ_ML^h in eq. (9)** is the robot's local ``(1/N) P_i⁻¹(t)`` after the hypothesis rounds
  (Sec. III: ``Λ_ML^h = (1/N) lim P_i⁻¹``); robots know ``N``.
* **Eq. (9) as printed.** For a member the exact covariance of ``x_i − θ_ML^h`` is
  ``Λ_i − Λ_ML^h`` (``Cov(x_i, θ_ML^h) = Λ_ML^h``); eq. (9) gives
  ``Λ_ML^h + Λ_i − 2 Λ_ML^h Λ_i⁻¹ Λ_ML^h``, the same for ``c = 1`` (``Λ_ML^h = Λ_i``) and
  larger (positive semidefinite difference) for ``c ≥ 2``: a looser gate. We use eq. (9) as
  printed, to reproduce the paper.
* **Winner and inliers**: each robot picks ``h* = argmax_h v_i^h`` from its own vote vector
  and counts itself an inlier iff its own current vote for ``h*`` is yes (static: its eq.-(8)
  vote; dynamic: its gate at the last round). Ties (:func:`pick_winner`): votes within
  ``tie_tol`` of the largest count as tied and the lowest index among them wins. A vote is a
  count over ``N`` (``|Y_h| / N`` at the limit), so two different counts differ by at least
  ``1 / N``; :data:`VOTE_TIE_TOL` (``1e-4``) is chosen far above float32 rounding (``6e-8``
  relative per round, accumulated over a 100-round cap) and far below ``1 / N``, so neither
  the wire precision nor a summation order decides a tie. ``tie_tol = 0`` is the plain ``argmax`` (the fixed-round
  scheme as it ran before, kept as the reference). The exact mode
  (:mod:`pipeline.fusion.flooding`) compares integer counts.
* **Initial opinion** (eq. 13 at ``t = 0``): a member of ``V_h`` starts voting (eq. 10), so
  its previous opinion is "yes"; every other robot's is "no".
* **Rounds**: max-c consensus runs ``maxc_rounds`` rounds before the consensus; they are
  counted apart (``maxc_stats``), as the paper's "iterations" count only the consensus.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import gammaincinv

from pipeline.errors import InputError
from pipeline.fusion.consensus import (
    CommStats,
    Topology,
    as_topology,
    average_consensus,
    bundle_bytes,
    hypothesis_members,
    information_form,
    max_c_consensus,
    ml_consensus,
    solve_information,
    whole_count,
)

__all__ = [
    "VotingResult",
    "chi2_ppf",
    "gate_threshold",
    "distributed_ml",
    "static_voting",
    "dynamic_voting",
    "choose_hypotheses",
    "pick_winner",
    "VOTE_TIE_TOL",
    "sq_mahalanobis",
]

GATES = ("distance", "squared")
#: votes closer than this to the largest count as tied (module docstring, "Winner")
VOTE_TIE_TOL = 1e-4


def pick_winner(v: np.ndarray, tie_tol: float = VOTE_TIE_TOL) -> np.ndarray:
    """``h* = argmax_h v^h`` over the last axis; votes within ``tie_tol`` of the largest are
    tied and the lowest index among them wins (``tie_tol = 0``: plain ``argmax``).

    Examples
    --------
    >>> pick_winner(np.array([[0.5, 0.50000004, 0.2], [0.2, 0.6, 0.2]])).tolist()
    [0, 1]
    """
    v = np.asarray(v, dtype=np.float64)
    if tie_tol <= 0:
        return np.argmax(v, axis=-1)
    return np.argmax(v >= v.max(axis=-1, keepdims=True) - tie_tol, axis=-1)


def winning_view(theta: np.ndarray, ok: np.ndarray, yes: np.ndarray, v: np.ndarray,
                 tie_tol: float = VOTE_TIE_TOL):
    """Each robot's view under its winning hypothesis (:func:`pick_winner` on ``v``).

    Parameters
    ----------
    theta : (M, K, d); ok, yes : (M, K) — per robot-node and hypothesis
    v : (..., K) votes with ``prod(...) == M``

    Returns
    -------
    winner : (...) int; theta_w : (M, d); ok_w, yes_w : (M,)
    """
    winner = pick_winner(v, tie_tol)
    pick = winner.reshape(-1, 1)
    return (winner, np.take_along_axis(theta, pick[..., None], 1)[:, 0],
            np.take_along_axis(ok, pick, 1)[:, 0], np.take_along_axis(yes, pick, 1)[:, 0])


@dataclass
class VotingResult:
    """Each robot's final view after a fusion run.

    Attributes
    ----------
    theta : ndarray, (B, N, d)
        Robot's estimate of ``θ`` (for its winning hypothesis); 0 where ``valid`` is false.
    valid : ndarray, (B, N) bool
        The robot's ``P`` is invertible, so ``theta`` is defined.
    inlier : ndarray, (B, N) bool
        The robot's observation is part of its final estimate.
    winner : ndarray, (B, N) int
        Hypothesis ``h*`` the robot selected (0 for the non-robust ML).
    votes : ndarray, (B, N, K)
        Final vote vectors ``v_i`` (the fraction of robots voting each hypothesis).
    members : ndarray, (B, N, K) bool
        ``V_h`` of eq. (7).
    stats : CommStats
        Consensus rounds, messages and bytes (hypotheses, votes, final ML).
    maxc_stats : CommStats
        Max-c consensus (eq. 6) that chose the members.
    history : dict or None
        With ``history=True``: ``theta`` (T+1, B, N, K, d), ``valid`` (T+1, B, N, K) bool
        (``P_i`` invertible), ``yes`` (T+1, B, N, K) bool (the gate), ``v`` (T+1, B, N, K).
    """

    theta: np.ndarray
    valid: np.ndarray
    inlier: np.ndarray
    winner: np.ndarray
    votes: np.ndarray
    members: np.ndarray
    stats: CommStats
    maxc_stats: CommStats = field(default_factory=CommStats)
    history: dict | None = None
    settled: bool | None = None  # a round protocol's stop rule fired (not the cap)
    cycles: int | None = None    # exact mode: rows whose gate iteration ended in a cycle


def chi2_ppf(p: float, d: int) -> float:
    """Quantile ``χ²_{d,p}`` of the chi-square distribution with ``d`` degrees of freedom.

    ``2 · P⁻¹(d/2, p)`` with ``P`` the regularized lower incomplete gamma function: the same
    formula (and so the same float) as ``scipy.stats.chi2.ppf(p, d)``, without importing
    ``scipy.stats``.
    """
    return float(2.0 * gammaincinv(d / 2, p))


def gate_threshold(d: int, p: float, gate: str) -> float:
    """Threshold on the *squared* Mahalanobis distance for the chi-square gate.

    ``gate="squared"``: ``χ²_{d,p}``; ``gate="distance"`` (literal eqs. 8/12):
    ``(χ²_{d,p})²``, since ``sqrt(r) <= χ²_{d,p}`` iff ``r <= (χ²_{d,p})²``.
    """
    if gate not in GATES:
        raise InputError(f"gate must be one of {GATES}, got {gate!r}")
    if not 0 < p < 1:
        raise InputError(f"chi-square confidence p must be in (0, 1), got {p}")
    q = chi2_ppf(p, d)
    return q * q if gate == "distance" else q


def _prepare(x, cov, observed):
    """Validate and reshape to ``(B, N, d)``, ``(B, N, d, d)``, ``(B, N)``."""
    x = np.asarray(x, dtype=np.float64)
    cov = np.asarray(cov, dtype=np.float64)
    if x.ndim == 2:
        x = x[None]
        cov = cov[None] if cov.ndim == 3 else cov
        if observed is not None:
            observed = np.asarray(observed)[None]
    if x.ndim != 3:
        raise InputError(f"x must have shape (N, d) or (B, N, d), got {x.shape}")
    B, N, d = x.shape
    if cov.shape != (B, N, d, d):
        raise InputError(f"cov must have shape {(B, N, d, d)} to match x, got {cov.shape}")
    obs = np.ones((B, N), dtype=bool) if observed is None else np.asarray(observed, dtype=bool)
    if obs.shape != (B, N):
        raise InputError(f"observed must have shape {(B, N)}, got {obs.shape}")
    x = np.where(obs[..., None], x, 0.0)
    cov = np.where(obs[..., None, None], cov, np.eye(d))
    if not (np.isfinite(x).all() and np.isfinite(cov).all()):
        raise InputError("x and cov must be finite for every observing robot")
    if not np.allclose(cov, np.swapaxes(cov, -1, -2), rtol=1e-8, atol=1e-12):
        raise InputError("cov must be symmetric")
    ev = np.linalg.eigvalsh(cov)
    if (ev[..., 0] <= 0).any():
        b, i = np.argwhere(ev[..., 0] <= 0)[0]
        raise InputError(f"cov of robot {i} (problem {b}) is not positive definite "
                         f"(smallest eigenvalue {ev[b, i, 0]:.3g}); every observation needs "
                         "an invertible covariance")
    return x, cov, obs


def choose_hypotheses(observed, topology, K: int, c: int, rng, maxc_rounds: int | None = None,
                      *, before_round=None, draws=None):
    """``V_h`` for ``K`` hypotheses by max-c consensus on random draws (eqs. 6–7).

    Parameters
    ----------
    observed : ndarray, (B, N) bool — only observing robots may be drawn
    topology : Topology or (E, 2) edges
    K, c : int
    rng : numpy Generator or seed
    maxc_rounds : int or None — default ``N − 1``, a bound on the diameter of a connected
        graph of ``N`` robots
    before_round : callable or None — see :func:`~pipeline.fusion.consensus.max_c_consensus`
    draws : ndarray, (B, N, K) or None — each robot's own draws ``h_i ∈ (0, 1]``
        (:func:`pipeline.fusion.protocol.hypothesis_draws`) instead of drawing from ``rng``

    Returns
    -------
    members : ndarray, (B, N, K) bool;  stats : CommStats
    """
    obs = np.asarray(observed, dtype=bool)
    B, N = obs.shape
    if draws is None:
        draws = 1.0 - np.random.default_rng(rng).random((B * N, K))  # h_i in (0, 1]
    else:
        draws = np.array(draws, dtype=np.float64).reshape(B * N, K)
    draws[~obs.reshape(-1)] = -np.inf
    topo = as_topology(topology, N, B)
    rounds = N - 1 if maxc_rounds is None else int(maxc_rounds)
    sets, stats = max_c_consensus(draws, topo, c, rounds, before_round=before_round)
    return hypothesis_members(draws, sets).reshape(B, N, K), stats


def distributed_ml(x, cov, topology, rounds: int = 100, *, observed=None,
                   history: bool = False) -> VotingResult:
    """Non-robust distributed ML of all observations (eqs. 1–3; the paper's ref. [12]).

    Parameters
    ----------
    x : ndarray, (B, N, d) or (N, d)
    cov : ndarray, (B, N, d, d) or (N, d, d)
    topology : Topology over ``N`` or ``B N`` nodes, or (E, 2) robot edges
    rounds : int
    observed : ndarray, (B, N) bool or None — robots without an observation relay only

    Returns
    -------
    VotingResult with ``K = 1``; every observing robot is an "inlier".
    """
    rounds = whole_count(rounds, "rounds", 0)  # -1 ran no round: the estimates came back as given
    x, cov, obs = _prepare(x, cov, observed)
    B, N, d = x.shape
    topo = as_topology(topology, N, B)
    P0, q0 = information_form(x, cov, obs)
    out = ml_consensus(P0.reshape(B * N, d, d), q0.reshape(B * N, d), topo, rounds,
                       history=history)
    theta, _, _, ok, stats = out[:5]
    hist = None
    if history:
        hist = dict(theta=out[5].reshape(-1, B, N, 1, d))
    return VotingResult(theta=theta.reshape(B, N, d), valid=ok.reshape(B, N), inlier=obs.copy(),
                        winner=np.zeros((B, N), dtype=np.int64),
                        votes=np.broadcast_to(obs.mean(1)[:, None, None], (B, N, 1)).copy(),
                        members=obs[..., None].copy(), stats=stats, history=hist)


def _input_bundles(x, cov, obs, members):
    """Every node's input bundle and the vote's start, rows flattened to ``M = B·N``.

    Returns ``info`` (M, 1, d, d) — ``Λ_i⁻¹``, also the ``P`` part of the input bundle ``u``
    of eq. (14) —, ``xf`` (M, 1, d), ``obs_f`` (M, 1), ``u_q = Λ_i⁻¹ x_i`` (M, 1, d), and the
    start ``P(0)``, ``q(0)`` of eq. (5) and ``v(0)`` of eq. (10), masked by ``members``.
    """
    B, N, d = x.shape
    M = B * N
    info = information_matrix(cov).reshape(M, 1, d, d)
    xf = x.reshape(M, 1, d)
    u_q = (info @ xf[..., None])[..., 0]
    m = members.reshape(M, members.shape[-1]).astype(np.float64)
    return (info, xf, obs.reshape(M, 1), u_q, info * m[..., None, None],   # eq. (5)
            u_q * m[..., None], m)                                         # eq. (10)


def sq_mahalanobis(r, info):
    """``r' Λ⁻¹ r`` batched; ``r`` (..., d), ``info`` (..., d, d)."""
    return np.einsum("...i,...ij,...j->...", r, info, r)


def _voting_setup(x, cov, observed, topology, p, gate, K, c, rng, members, maxc_rounds,
                  before_round=None, draws=None):
    """Shared start of both voting schemes: checked inputs, topology, χ² gate, and the
    hypothesis members (max-c consensus, eqs. 6–7, unless given)."""
    if members is None:  # numpy's reshape / negative-dimension errors deep in max-c
        K = whole_count(K, "K (hypotheses)", 1)
    x, cov, obs = _prepare(x, cov, observed)
    B, N, d = x.shape
    topo = as_topology(topology, N, B)
    thr = gate_threshold(d, p, gate)
    if members is None:
        members, maxc_stats = choose_hypotheses(obs, topo, K, c, rng, maxc_rounds,
                                                before_round=before_round, draws=draws)
    else:
        members = np.asarray(members, dtype=bool) & obs[..., None]
        maxc_stats = CommStats()
    return x, cov, obs, topo, thr, members, maxc_stats


def static_voting(x, cov, topology, *, K: int, c: int = 1, p: float = 0.95,
                  gate: str = "distance", rounds=(100, 100, 100), rng=None, members=None,
                  observed=None, maxc_rounds: int | None = None,
                  tie_tol: float = VOTE_TIE_TOL) -> VotingResult:
    """Distributed static voting (Sec. IV-A): hypotheses, votes, vote averaging, final ML.

    Parameters
    ----------
    x, cov, topology, observed : as in :func:`distributed_ml`
    K, c : int — hypotheses and robots per hypothesis
    p : float — chi-square confidence of eq. (8)
    gate : ``"distance"`` or ``"squared"`` (module docstring)
    rounds : (int, int, int) — consensus rounds of the three steps: hypotheses (eqs. 2, 5),
        vote averaging, final ML of the winners
    rng : seed or Generator for the max-c draws
    members : ndarray, (B, N, K) bool or None — give ``V_h`` directly instead of drawing
    maxc_rounds : int or None — see :func:`choose_hypotheses`
    tie_tol : float — votes this close count as tied (:func:`pick_winner`)

    Returns
    -------
    VotingResult
    """
    x, cov, obs, topo, thr, members, maxc_stats = _voting_setup(
        x, cov, observed, topology, p, gate, K, c, rng, members, maxc_rounds)
    B, N, d = x.shape
    if np.ndim(rounds) != 1 or len(rounds) != 3:
        raise InputError(f"rounds must be three counts (hypotheses, vote averaging, final ML), "
                         f"got {rounds!r}")
    r_hyp, r_vote, r_final = (whole_count(r, "rounds", 0) for r in rounds)
    K = members.shape[-1]
    info = np.linalg.inv(cov)                                      # (B, N, d, d)
    # step 1: the K partial MLs (eq. 4) by consensus with initial conditions (5)
    P0, q0 = information_form(x[:, :, None], cov[:, :, None], members)   # (B, N, K, ...)
    theta_h, P_h, _, ok_h, st1 = ml_consensus(P0.reshape(B * N, K, d, d),
                                              q0.reshape(B * N, K, d), topo, r_hyp)
    theta_h = theta_h.reshape(B, N, K, d)
    ok_h = ok_h.reshape(B, N, K)
    # step 2: votes, eq. (8) with the covariance of eq. (9)
    P_h = P_h.reshape(B, N, K, d, d)
    safe = np.where(ok_h[..., None, None], P_h, np.eye(d))
    cov_ml = np.linalg.inv(safe) / N                              # Λ_ML^h = (1/N) P_i⁻¹
    cov_i = cov[:, :, None]
    cov_out = cov_ml + cov_i                                      # eq. (9), i ∉ V_h
    cov_in = cov_ml + cov_i - 2 * cov_ml @ info[:, :, None] @ cov_ml   # eq. (9), i ∈ V_h
    cov_ih = np.where(members[..., None, None], cov_in, cov_out)
    cov_ih = 0.5 * (cov_ih + np.swapaxes(cov_ih, -1, -2))
    # "positive definite" relative to the robot's own Λ_i: eq. (9) is a difference of
    # matrices of that size, so round-off leaves ~1e-16 of it where the exact value is 0
    ev = np.linalg.eigvalsh(cov_ih)
    scale = np.trace(cov_i, axis1=-2, axis2=-1)
    pd = ev[..., 0] > 1e-8 * scale
    safe_c = np.where(pd[..., None, None], cov_ih, np.eye(d))
    r = x[:, :, None] - theta_h
    dist_sq = sq_mahalanobis(r, np.linalg.inv(safe_c))
    vote0 = ok_h & obs[..., None] & np.where(pd, dist_sq <= thr, members)
    # step 3: average the votes
    v, st2 = average_consensus(vote0.astype(np.float64).reshape(B * N, K), topo, r_vote)
    v = v.reshape(B, N, K)
    winner = pick_winner(v, tie_tol)
    inlier = np.take_along_axis(vote0, winner[..., None], -1)[..., 0]
    # step 4: final ML of the robots that voted for the winner
    P0, q0 = information_form(x, cov, inlier)
    theta, _, _, ok, st3 = ml_consensus(P0.reshape(B * N, d, d), q0.reshape(B * N, d), topo,
                                        r_final)
    return VotingResult(theta=theta.reshape(B, N, d), valid=ok.reshape(B, N), inlier=inlier,
                        winner=winner, votes=v, members=members, stats=st1 + st2 + st3,
                        maxc_stats=maxc_stats)


@dataclass
class RoundProtocol:
    """How a dynamic-voting run meets the robots' network (:mod:`pipeline.fusion.protocol`).

    Attributes
    ----------
    traffic : LinkTraffic — the flat-node edges (the consensus graph) and their comm links
    n_robots : int — team size (public): bounds every observer graph's diameter
    stop_window : int — ``W`` of the stop rule (``>=`` every observer graph's diameter)
    wire : ``"float32"`` or ``"float64"`` — precision of the consensus messages (and so of the
        robots' consensus state, which is what they send)
    exchange : CountingExchange or LockstepExchange — carries every logical round
    """

    traffic: object
    n_robots: int
    stop_window: int
    wire: str = "float32"
    exchange: object = None


def dynamic_voting(x, cov, topology, *, K: int, c: int = 1, p: float = 0.95,
                   gate: str = "distance", rounds: int = 100, rng=None, members=None,
                   observed=None, maxc_rounds: int | None = None,
                   history: bool = False, protocol: RoundProtocol | None = None,
                   tie_tol: float = VOTE_TIE_TOL, draws=None) -> VotingResult:
    """Distributed dynamic voting (Sec. IV-B, eqs. 10–14).

    Every hypothesis ``h`` carries ``(P_i, q_i, v_i)`` per robot, initialized by eqs. (5) and
    (10). Each round robot ``i`` tests ``d_i(t) = d(x_i, θ_i(t), Λ_i)`` (eq. 12; no vote
    while ``P_i(t)`` is singular), compares the outcome with its previous one (eq. 13), and
    adds ``u_i = ±(Λ_i⁻¹, Λ_i⁻¹ x_i, 1)`` to the consensus update (eqs. 11, 14). One message
    per neighbour and round carries all ``K`` bundles ``(P, q, v)``.

    Parameters
    ----------
    x, cov, topology, observed : as in :func:`distributed_ml`
    K, c : int — hypotheses and robots per hypothesis
    p, gate : chi-square gate (module docstring)
    rounds : int — consensus rounds
    rng : seed or Generator for the max-c draws
    members : ndarray, (B, N, K) bool or None — give ``V_h`` directly instead of drawing
    maxc_rounds : int or None — see :func:`choose_hypotheses`
    history : bool — keep ``θ_i^h(t)``, the gate outcome and ``v_i^h(t)`` of every round
    protocol : RoundProtocol or None
        ``None``: ``rounds`` rounds on ``topology``, messages counted as full float64 bundles
        (the paper's fixed-round scheme). Given: the robots run on ``protocol.traffic``'s
        graph (``topology`` must be the same graph), send only the tracks a link carries and
        only what changed, at ``protocol.wire`` precision, and stop by the distributed rule
        of :mod:`pipeline.fusion.protocol` (``rounds`` is then a cap); every logical round,
        max-c ones included, is carried by ``protocol.exchange``.
    tie_tol : float — votes this close count as tied (:func:`pick_winner`)
    draws : ndarray, (B, N, K) or None — the robots' own max-c draws instead of ``rng``'s
        (see :func:`choose_hypotheses`)

    Returns
    -------
    VotingResult
        ``theta`` is ``θ_i^{h*}(T)``; ``inlier`` is robot ``i``'s gate for ``h*`` at ``T``.
    """
    rounds = whole_count(rounds, "rounds", 0)  # -1 ran no round: the estimates came back as given
    before_round = None
    if protocol is not None:
        if history:
            raise InputError("dynamic_voting: history is not kept with a round protocol")
        live = _LiveGraph(protocol, int(np.asarray(x).shape[-2]) * (
            1 if np.asarray(x).ndim == 2 else int(np.asarray(x).shape[0])))
        topology = live
        before_round = live.maxc_round(K, c)
    x, cov, obs, topo, thr, members, maxc_stats = _voting_setup(
        x, cov, observed, topology, p, gate, K, c, rng, members, maxc_rounds, before_round,
        draws)
    if protocol is not None:
        return _dynamic_voting_protocol(x, cov, obs, live, thr, members, maxc_stats, rounds,
                                        protocol, tie_tol)
    B, N, d = x.shape
    K = members.shape[-1]
    M = B * N
    info, xf, obs_f, u_q, P, q, v = _input_bundles(x, cov, obs, members)
    u_P = info
    prev_yes = members.reshape(M, K).copy()
    stats = CommStats()
    msg = bundle_bytes(K * (d * (d + 1) // 2 + d + 1))

    def opinion(P, q):
        theta, ok = solve_information(P, q)
        r = xf - theta
        yes = ok & obs_f & (sq_mahalanobis(r, info) <= thr)      # eq. (12), gate
        return theta, ok, yes

    hist = dict(theta=[], valid=[], yes=[], v=[]) if history else None

    def record(theta, ok, yes, v):
        if history:
            hist["theta"].append(theta.reshape(B, N, K, d))
            hist["valid"].append(ok.reshape(B, N, K))
            hist["yes"].append(yes.reshape(B, N, K))
            hist["v"].append(v.reshape(B, N, K))

    from pipeline.progress import progress

    for t in progress(range(int(rounds)), desc="fusion rounds (dynamic voting)"):
        theta, ok, yes = opinion(P, q)
        record(theta, ok, yes, v)
        u = yes.astype(np.float64) - prev_yes                       # eqs. (13)–(14): ±1 or 0
        prev_yes = yes
        A = topo.weights(t)
        stats.add_round(len(topo.edges(t)), msg)
        P = (A @ P.reshape(M, -1)).reshape(P.shape) + u[..., None, None] * u_P   # eq. (11)
        q = (A @ q.reshape(M, -1)).reshape(q.shape) + u[..., None] * u_q
        v = A @ v + u
    theta, ok, yes = opinion(P, q)
    record(theta, ok, yes, v)
    if history:
        hist = {k: np.stack(val) for k, val in hist.items()}
    v = v.reshape(B, N, K)
    winner, theta_w, ok_w, yes_w = winning_view(theta, ok, yes, v, tie_tol)
    return VotingResult(theta=theta_w.reshape(B, N, d), valid=ok_w.reshape(B, N),
                        inlier=yes_w.reshape(B, N), winner=winner, votes=v, members=members,
                        stats=stats, maxc_stats=maxc_stats, history=hist)


def information_matrix(cov: np.ndarray) -> np.ndarray:
    """``Λ⁻¹`` of covariances ``(..., d, d)``, exactly symmetric: ``(L + Lᵀ) / 2`` of the
    inverse ``L`` (the two halves of the sum are the same floats, so the result is)."""
    info = np.linalg.inv(cov)
    return 0.5 * (info + np.swapaxes(info, -1, -2))


class _LiveGraph(Topology):
    """The consensus graph of a :class:`RoundProtocol` run: its flat-node edges minus the
    comm links the exchange reported lost (a crashed robot leaves the graph)."""

    def __init__(self, protocol: RoundProtocol, n_nodes: int):
        from pipeline.fusion.consensus import _metropolis

        self.protocol = protocol
        self.n_nodes = int(n_nodes)
        self.edges_all = protocol.traffic.node_edges
        self.alive = np.ones(len(self.edges_all), dtype=bool)
        self._weights = _metropolis  # the protocol's own edges: each once, in range
        self._A = None

    def edges(self, t: int) -> np.ndarray:
        return self.edges_all[self.alive]

    def weights(self, t: int = 0):
        if self._A is None:
            self._A = self._weights(self.edges(t), self.n_nodes)
        return self._A

    def degree(self) -> np.ndarray:
        e = self.edges(0)
        return np.bincount(e.reshape(-1), minlength=self.n_nodes)

    def carry(self, kind: str, running: np.ndarray, changed: np.ndarray, changed_bytes: int,
              counter_bytes: int) -> bool:
        """Send one logical round through the exchange; True when the graph lost links."""
        from pipeline.fusion.protocol import message_bytes

        pr = self.protocol
        run, chg = pr.traffic.directed(running, changed, self.alive)
        up = pr.exchange.round(kind, message_bytes(run, chg, changed_bytes, counter_bytes))
        alive = self.alive & up[pr.traffic.edge_link]
        if (alive != self.alive).any():
            self.alive = alive
            self._A = None
            return True
        return False

    def maxc_round(self, K: int, c: int):
        everyone = np.ones(self.n_nodes, dtype=bool)

        def before_round(t, changed):
            self.carry("fusion-maxc", everyone, changed, 8 * K * c, 0)

        return before_round


def _dynamic_voting_protocol(x, cov, obs, live: _LiveGraph, thr, members, maxc_stats,
                             rounds: int, protocol: RoundProtocol,
                             tie_tol: float = VOTE_TIE_TOL) -> VotingResult:
    """Dynamic voting (eqs. 10–14) with per-link delta messages and the distributed stop
    rule of :mod:`pipeline.fusion.protocol`; vectorized over all robots and tracks: row
    ``i`` of every array is robot ``i``'s own state, and its update reads only that and its
    neighbours' messages (their wire images)."""
    from pipeline.fusion.protocol import bundle_reals, index_bytes, stop_counters, to_wire

    B, N, d = x.shape
    K = members.shape[-1]
    M = B * N
    wire = protocol.wire
    W = int(protocol.stop_window)
    counter_bytes = index_bytes(W + 1)
    changed_bytes = (index_bytes(protocol.n_robots) + bundle_reals(K, d)
                     * np.dtype(np.float32 if wire == "float32" else np.float64).itemsize)
    # Λ⁻¹ is exactly symmetric (information_matrix), so every P is too and the upper
    # triangle a message carries is all of it
    info, xf, obs_f, u_q, P, q, v = _input_bundles(x, cov, obs, members)
    u_P = info
    P, q = to_wire(P, wire), to_wire(q, wire)
    prev_yes = members.reshape(M, K).copy()
    stopped = np.zeros(M, dtype=bool)
    counter = np.zeros(M, dtype=np.int64)
    sent = None
    deg = live.degree()
    deg_changed = np.zeros(M, dtype=bool)
    theta = np.zeros((M, K, d))
    ok = np.zeros((M, K), dtype=bool)
    yes = prev_yes.copy()

    from pipeline.progress import progress

    t_run = 0
    for t in progress(range(int(rounds)), desc="fusion rounds (dynamic voting)"):
        run = ~stopped
        th, okr = solve_information(P[run], q[run])                  # θ_i = P_i⁻¹ q_i
        theta[run], ok[run] = th, okr
        yes[run] = okr & obs_f[run] & (sq_mahalanobis(xf[run] - th, info[run]) <= thr)  # eq. 12
        u = yes.astype(np.float64) - prev_yes                       # eqs. (13)–(14)
        prev_yes = yes.copy()
        # what the messages of this round carry: the state's wire image, sent again only
        # where it changed (or the sender's degree did)
        image = (to_wire(P, wire), to_wire(q, wire), to_wire(v, wire))
        changed = np.ones(M, dtype=bool) if sent is None else deg_changed.copy()
        if sent is not None:
            for now_, before in zip(image, sent, strict=True):
                changed |= (now_ != before).reshape(M, -1).any(1)
        sent = image
        # the stop rule's flag: nothing changed in the last round and no opinion changes now
        flag = ~changed & (u == 0).all(1)
        counter = stop_counters(counter, flag, live.edges(t), stopped)
        stopping = run & (counter >= W + 1)
        if live.carry("fusion", run, changed, changed_bytes, counter_bytes):
            new_deg = live.degree()
            deg_changed = new_deg != deg
            deg = new_deg
        else:
            deg_changed = np.zeros(M, dtype=bool)
        stopped |= stopping
        t_run = t + 1
        if stopped.all():
            break
        run = ~stopped
        # eq. (11) on the values as sent: a robot's state is what it puts on the wire
        A = live.weights(t)
        Pn = (A @ image[0].reshape(M, -1)).reshape(P.shape) + u[..., None, None] * u_P
        qn = (A @ image[1].reshape(M, -1)).reshape(q.shape) + u[..., None] * u_q
        vn = A @ image[2] + u
        P[run], q[run], v[run] = (to_wire(a[run], wire) for a in (Pn, qn, vn))
    run = ~stopped
    if run.any():                                                   # the cap was reached
        th, okr = solve_information(P[run], q[run])
        theta[run], ok[run] = th, okr
        yes[run] = okr & obs_f[run] & (sq_mahalanobis(xf[run] - th, info[run]) <= thr)
    stats = CommStats(rounds=t_run)
    v = v.reshape(B, N, K)
    winner, theta_w, ok_w, yes_w = winning_view(theta, ok, yes, v, tie_tol)
    return VotingResult(theta=theta_w.reshape(B, N, d), valid=ok_w.reshape(B, N),
                        inlier=yes_w.reshape(B, N), winner=winner, votes=v, members=members,
                        stats=stats, maxc_stats=maxc_stats, settled=bool(stopped.all()))
