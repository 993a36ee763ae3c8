"""Consensus building blocks for distributed fusion (Montijano, Martínez, Sagüés, Secs. II–III).

Implements, for a robot network whose communication graph ``G(t)`` may change every round
(Assumption 2.1):

* Metropolis weights ``A(t)`` for the current graph (the paper's Sec. V choice, from its
  ref. [12], Xiao–Boyd–Lall);
* average consensus ``x(t+1) = A(t) x(t)`` (eq. 2), and on top of it the distributed
  maximum likelihood ``θ_i = P_i⁻¹ q_i`` (eqs. 1–3, initial conditions eq. 5);
* max-c consensus on random draws, which picks the ``c`` robots of a hypothesis (eqs. 6–7);
* the RANSAC number of hypotheses and its success probability (Sec. III, ref. [5]).

The distributed model (docs/DESIGN.md, "the one rule")
-------------------------------------------------
A robot uses only its own state and the messages received from its current neighbours.
One round of consensus over all robots is computed here in matrix form,
``X(t+1) = A(t) X(t)``, where ``A(t)`` has exactly the sparsity of ``G(t)`` plus the
diagonal: row ``i`` combines robot ``i``'s own value with the values of its neighbours
``N_i(t)`` — precisely the messages robot ``i`` received that round — and nothing else.
The Metropolis weight ``a_ij = 1 / (1 + max(deg_i, deg_j))`` needs only robot ``i``'s own
degree (the number of messages it received) and ``deg_j``, which robot ``j`` puts in its
message. The matrix form is a vectorized evaluation of the ``N`` local updates, not a
central computation: no robot reads another robot's state outside a message.

Many independent problems (Monte Carlo trials, or landmarks) run at once on a *flat node
set*: node ``b * N + i`` is robot ``i`` of problem ``b``. A topology over the flat nodes is
block diagonal (problems never exchange values); :func:`replicate` expands one robot graph
to all problems.

Message accounting
------------------
Each round every robot sends one message to each current neighbour, so a round costs
``2 |E(t)|`` messages per problem (one per direction of every edge). A message carries one
*quantity bundle*, encoded as little-endian float64 per real number, a symmetric ``d × d``
matrix as its ``d (d + 1) / 2`` upper-triangle entries, plus the sender's degree as a
uint16 (2 bytes) for the Metropolis weights. :class:`CommStats` adds these up;
:func:`bundle_bytes` gives the size of one message.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import shortest_path

from pipeline.commgraph import check_comm_edges
from pipeline.errors import InputError
from pipeline.transport import Transport

__all__ = [
    "CommStats",
    "Topology",
    "FixedTopology",
    "SwitchingTopology",
    "RandomGeometricTopology",
    "TransportTopology",
    "replicate",
    "as_topology",
    "metropolis_weights",
    "bundle_bytes",
    "DEGREE_BYTES",
    "average_consensus",
    "ml_consensus",
    "max_c_consensus",
    "top_c_distinct",
    "hypothesis_members",
    "information_form",
    "solve_information",
    "ransac_hypotheses",
    "ransac_success",
    "graph_diameter",
]

#: bytes of the sender's degree carried in every message (uint16), for Metropolis weights
DEGREE_BYTES = 2
#: bytes of one real number in a message (float64)
REAL_BYTES = 8


# --------------------------------------------------------------------------------------------
# message accounting


@dataclass
class CommStats:
    """Rounds, messages and bytes exchanged by a distributed computation.

    Attributes
    ----------
    rounds : int
        Synchronous communication rounds.
    messages : int
        Messages sent, ``Σ_t 2 |E(t)|`` summed over all problems run at once.
    bytes : int
        Payload bytes of those messages in the encoding of the module docstring.
    """

    rounds: int = 0
    messages: int = 0
    bytes: int = 0

    def add_round(self, n_edges: int, message_bytes: int) -> None:
        """Count one round over a graph with ``n_edges`` undirected edges."""
        self.rounds += 1
        self.messages += 2 * int(n_edges)
        self.bytes += 2 * int(n_edges) * int(message_bytes)

    def __add__(self, other: CommStats) -> CommStats:
        return CommStats(self.rounds + other.rounds, self.messages + other.messages,
                         self.bytes + other.bytes)

    def as_dict(self) -> dict:
        return dict(rounds=self.rounds, messages=self.messages, bytes=self.bytes)


def bundle_bytes(n_reals: int, *, with_degree: bool = True) -> int:
    """Bytes of one message carrying ``n_reals`` float64 values (plus the sender's degree)."""
    return REAL_BYTES * int(n_reals) + (DEGREE_BYTES if with_degree else 0)


# --------------------------------------------------------------------------------------------
# topologies


class Topology(ABC):
    """A communication graph sequence ``G(t)`` over ``n_nodes`` flat nodes.

    Subclasses implement :meth:`edges`; ``edges(t)`` is the ``(E, 2)`` int64 array of the
    undirected edges of round ``t`` (each stored once, no self-loops).
    """

    n_nodes: int

    @abstractmethod
    def edges(self, t: int) -> np.ndarray:
        """Edges of round ``t``."""

    def weights(self, t: int) -> sp.csr_matrix:
        """Metropolis matrix ``A(t)``, ``(n_nodes, n_nodes)``."""
        return _metropolis(self.edges(t), self.n_nodes)


def _check_edges(edges, n_nodes: int) -> np.ndarray:
    """The one edge checker (:func:`pipeline.commgraph.check_comm_edges`) on flat nodes; sorted."""
    return np.unique(check_comm_edges(edges, n_nodes, what="edge", noun="node"), axis=0).reshape(-1, 2)


class FixedTopology(Topology):
    """The same graph every round.

    Parameters
    ----------
    edges : array_like, (E, 2) int
    n_nodes : int
    """

    def __init__(self, edges, n_nodes: int):
        self.n_nodes = int(n_nodes)
        self._edges = _check_edges(edges, self.n_nodes)
        self._A = _metropolis(self._edges, self.n_nodes)

    def edges(self, t: int) -> np.ndarray:
        return self._edges

    def weights(self, t: int) -> sp.csr_matrix:
        return self._A


class SwitchingTopology(Topology):
    """A graph given per round by a list (cycled) or a callable ``t -> edges``.

    Parameters
    ----------
    graphs : list of (E_t, 2) arrays, or callable ``t -> (E_t, 2)``
    n_nodes : int
    """

    def __init__(self, graphs: list | Callable[[int], np.ndarray], n_nodes: int):
        self.n_nodes = int(n_nodes)
        if callable(graphs):
            self._fn = graphs
            self._list = None
        else:
            if len(graphs) == 0:
                raise InputError("SwitchingTopology needs at least one graph")
            self._list = [_check_edges(g, self.n_nodes) for g in graphs]
            self._fn = None

    def edges(self, t: int) -> np.ndarray:
        if self._list is not None:
            return self._list[t % len(self._list)]
        return _check_edges(self._fn(t), self.n_nodes)


class RandomGeometricTopology(Topology):
    """Independent random geometric graphs, redrawn every round, for many problems at once.

    Every round each of the ``n_problems`` networks places its ``n_robots`` robots uniformly
    in the unit square and links the pairs closer than ``radius``; node ``b * n_robots + i``
    is robot ``i`` of problem ``b``. The graph of one round may be disconnected; over a few
    rounds the union is connected with high probability (Assumption 2.1 holds in practice,
    not by construction). Graphs are cached per round so that ``edges(t)`` is repeatable.

    Parameters
    ----------
    n_robots, n_problems : int
    radius : float
        Communication radius in units of the square's side.
    seed : int or numpy Generator
    """

    def __init__(self, n_robots: int, n_problems: int = 1, radius: float = 0.4, seed: int = 0):
        if n_robots < 1 or n_problems < 1:
            raise InputError(f"n_robots and n_problems must be >= 1, got {n_robots}, {n_problems}")
        if not radius > 0:
            raise InputError(f"radius must be > 0, got {radius}")
        self.n_robots, self.n_problems, self.radius = int(n_robots), int(n_problems), float(radius)
        self.n_nodes = self.n_robots * self.n_problems
        self.seed = int(seed)
        self._iu, self._ju = np.triu_indices(self.n_robots, k=1)
        self._last: tuple[int, np.ndarray] | None = None

    def positions(self, t: int) -> np.ndarray:
        """Robot positions of round ``t``, ``(n_problems, n_robots, 2)`` (a pure function of t)."""
        return np.random.default_rng([self.seed, int(t)]).random((self.n_problems,
                                                                  self.n_robots, 2))

    def edges(self, t: int) -> np.ndarray:
        if self._last is not None and self._last[0] == t:
            return self._last[1]
        pos = self.positions(t)
        d2 = ((pos[:, self._iu] - pos[:, self._ju]) ** 2).sum(-1)  # (B, pairs)
        b, k = np.nonzero(d2 < self.radius ** 2)
        off = b * self.n_robots
        e = np.stack([off + self._iu[k], off + self._ju[k]], axis=1)
        self._last = (t, e)
        return e


class TransportTopology(Topology):
    """The graph sequence of a :class:`~pipeline.transport.Transport`: ``G(t)`` = its links up
    in round ``t`` (:meth:`~pipeline.transport.Transport.edges`), over its ``n`` robots.

    Parameters
    ----------
    transport : Transport
    """

    def __init__(self, transport: Transport):
        self.transport = transport
        self.n_nodes = int(transport.n)

    def edges(self, t: int) -> np.ndarray:
        return _check_edges(self.transport.edges(t), self.n_nodes)


class _Replicated(Topology):
    def __init__(self, base: Topology, n_problems: int):
        self.base, self.n_problems = base, int(n_problems)
        self.n_nodes = base.n_nodes * self.n_problems
        self._last: tuple[int, np.ndarray] | None = None

    def edges(self, t: int) -> np.ndarray:
        e = self.base.edges(t)
        off = (np.arange(self.n_problems, dtype=np.int64) * self.base.n_nodes)[:, None, None]
        return (e[None] + off).reshape(-1, 2)

    def weights(self, t: int) -> sp.csr_matrix:
        if isinstance(self.base, FixedTopology):
            if self._last is None:
                self._last = (0, sp.kron(sp.identity(self.n_problems, format="csr"),
                                         self.base.weights(0), format="csr"))
            return self._last[1]
        return sp.kron(sp.identity(self.n_problems, format="csr"), self.base.weights(t),
                       format="csr")


def replicate(base: Topology, n_problems: int) -> Topology:
    """The robot graph ``base`` (over ``N`` robots) used by each of ``n_problems`` problems.

    Node ``b * N + i`` is robot ``i`` in problem ``b``; the weights are ``I_B ⊗ A(t)``.
    """
    if n_problems == 1:
        return base
    return _Replicated(base, n_problems)


def as_topology(topology, n_robots: int, n_problems: int = 1) -> Topology:
    """Normalize a topology argument to a :class:`Topology` over ``n_robots * n_problems`` nodes.

    Accepts a :class:`Topology` over all flat nodes, a :class:`Topology` over ``n_robots``
    (replicated to every problem), a :class:`~pipeline.transport.Transport` of ``n_robots``
    (its links per round, :class:`TransportTopology`), or an ``(E, 2)`` edge array over
    ``n_robots`` (fixed).
    """
    if isinstance(topology, Transport):
        topology = TransportTopology(topology)
    if not isinstance(topology, Topology):
        topology = FixedTopology(topology, n_robots)
    if topology.n_nodes == n_robots * n_problems:
        return topology
    if topology.n_nodes == n_robots:
        return replicate(topology, n_problems)
    raise InputError(f"topology has {topology.n_nodes} nodes; expected {n_robots} robots or "
                     f"{n_robots * n_problems} = {n_problems} problems x {n_robots} robots")


def metropolis_weights(edges, n_nodes: int) -> sp.csr_matrix:
    """Metropolis weights of an undirected graph (Xiao–Boyd–Lall, the paper's ref. [12]).

    ``a_ij = 1 / (1 + max(deg_i, deg_j))`` for ``(i, j) ∈ E``, ``a_ii = 1 − Σ_j a_ij``, zero
    elsewhere. The matrix is symmetric and doubly stochastic with a positive diagonal, as eq.
    (2) requires, for any graph — also a disconnected one or one that changes every round.

    Parameters
    ----------
    edges : array_like, (E, 2) int — undirected edges, each once
    n_nodes : int

    Returns
    -------
    A : scipy.sparse.csr_matrix, (n_nodes, n_nodes) float64

    Examples
    --------
    >>> metropolis_weights([[0, 1], [1, 2]], 3).toarray().round(3)
    array([[0.667, 0.333, 0.   ],
           [0.333, 0.333, 0.333],
           [0.   , 0.333, 0.667]])
    """
    return _metropolis(_check_edges(edges, int(n_nodes)), int(n_nodes))


def _metropolis(e: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """:func:`metropolis_weights` of edges already checked (each once, ids in range)."""
    i, j = e[:, 0], e[:, 1]
    deg = np.bincount(np.concatenate([i, j]), minlength=n_nodes)
    w = 1.0 / (1.0 + np.maximum(deg[i], deg[j]))
    diag = 1.0 - np.bincount(i, weights=w, minlength=n_nodes) - np.bincount(j, weights=w,
                                                                             minlength=n_nodes)
    nodes = np.arange(n_nodes)
    rows = np.concatenate([i, j, nodes])
    cols = np.concatenate([j, i, nodes])
    vals = np.concatenate([w, w, diag])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n_nodes, n_nodes))


def graph_diameter(edges, n_nodes: int) -> int:
    """Diameter (longest shortest path, in hops) of a connected graph; ``InputError`` if not."""
    if int(n_nodes) < 1:
        raise InputError(f"graph of {n_nodes} nodes: a diameter needs at least one node")
    e = _check_edges(edges, int(n_nodes))
    adj = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_nodes, n_nodes))
    dist = shortest_path(adj, directed=False, unweighted=True)
    if np.isinf(dist).any():
        raise InputError("the communication graph is disconnected: its diameter is infinite")
    return int(dist.max())


# --------------------------------------------------------------------------------------------
# average consensus and the distributed ML


def _mix(A: sp.csr_matrix, X: np.ndarray) -> np.ndarray:
    """One round ``X ← A X`` on the leading (node) axis; trailing axes are the bundle."""
    return (A @ X.reshape(X.shape[0], -1)).reshape(X.shape)


def average_consensus(x0, topology, rounds: int, *, history: bool = False):
    """Average consensus ``x_i(t+1) = a_ii x_i(t) + Σ_{j∈N_i(t)} a_ij x_j(t)`` (eq. 2).

    Parameters
    ----------
    x0 : array_like, (n_nodes, ...) float
        Initial value of each node; trailing axes are carried in one message.
    topology : Topology or (E, 2) edges
    rounds : int
    history : bool
        Also return every iterate.

    Returns
    -------
    x : ndarray, (n_nodes, ...)
        Values after ``rounds`` rounds; each connected component of the union graph tends to
        its initial average.
    stats : CommStats
        One bundle of ``x0[0].size`` reals per message.
    trace : ndarray, (rounds + 1, n_nodes, ...), only if ``history``
    """
    x = np.array(x0, dtype=np.float64)
    topo = as_topology(topology, x.shape[0])
    stats = CommStats()
    msg = bundle_bytes(x[0].size)
    trace = [x.copy()] if history else None
    for t in range(whole_count(rounds, "rounds", 0)):
        A = topo.weights(t)
        stats.add_round(len(topo.edges(t)), msg)
        x = _mix(A, x)
        if history:
            trace.append(x.copy())
    if history:
        return x, stats, np.stack(trace)
    return x, stats


def extreme_eigenvalues_sym3(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest eigenvalue of symmetric ``(..., 3, 3)`` matrices, closed form.

    Smith's trigonometric solution (O. K. Smith, "Eigenvalues of a symmetric 3 × 3 matrix",
    Comm. ACM 4(4), 1961). Vectorized numpy; about 10x faster than batched ``eigvalsh`` on
    the many small information matrices of the fusion stage, with an absolute error of a few
    ulps of the largest eigenvalue — far below the ``rtol`` of :func:`solve_information`.
    """
    a11, a22, a33 = A[..., 0, 0], A[..., 1, 1], A[..., 2, 2]
    a12, a13, a23 = A[..., 0, 1], A[..., 0, 2], A[..., 1, 2]
    off = a12 * a12 + a13 * a13 + a23 * a23
    m = (a11 + a22 + a33) / 3.0
    b11, b22, b33 = a11 - m, a22 - m, a33 - m
    p = np.sqrt((b11 * b11 + b22 * b22 + b33 * b33 + 2.0 * off) / 6.0)
    flat = p <= 0
    ps = np.where(flat, 1.0, p)
    # det(B) / 2 with B = (A - mI) / p
    det = (b11 * (b22 * b33 - a23 * a23) - a12 * (a12 * b33 - a23 * a13)
           + a13 * (a12 * a23 - b22 * a13)) / (ps * ps * ps)
    phi = np.arccos(np.clip(det / 2.0, -1.0, 1.0)) / 3.0
    hi = np.where(flat, m, m + 2.0 * p * np.cos(phi))
    lo = np.where(flat, m, m + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0))
    return lo, hi


def solve_information(P: np.ndarray, q: np.ndarray, *, rtol: float = 1e-10):
    """``θ = P⁻¹ q`` batched, with a flag where ``P`` is singular (or not positive definite).

    Parameters
    ----------
    P : ndarray, (..., d, d) symmetric
    q : ndarray, (..., d)
    rtol : float
        ``P`` counts as singular when its smallest eigenvalue is ``<= rtol`` times its largest
        absolute eigenvalue (or ``P = 0``).

    Returns
    -------
    theta : ndarray, (..., d) — zeros where singular
    ok : ndarray, (...) bool — ``P`` positive definite

    Notes
    -----
    An information matrix built by eq. (2) from non-negative weights is positive
    semidefinite; an indefinite ``P`` only appears transiently in dynamic voting, after a
    robot withdraws its observation (eq. 14, case ``T_i^-``). It is treated like a singular
    one: ``θ_i`` is then not a non-negative combination of observations (Sec. IV-C).
    """
    P = np.asarray(P, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    if P.shape[-1] == 3:
        lo, hi = extreme_eigenvalues_sym3(P)
    else:
        ev = np.linalg.eigvalsh(P)
        lo, hi = ev[..., 0], ev[..., -1]
    scale = np.maximum(np.abs(lo), np.abs(hi))
    ok = (lo > rtol * scale) & (scale > 0)
    d = P.shape[-1]
    safe = np.where(ok[..., None, None], P, np.eye(d))
    theta = np.linalg.solve(safe, q[..., None])[..., 0]
    theta[~ok] = 0.0
    return theta, ok


def information_form(x, cov, weight=None):
    """``P = w Λ⁻¹``, ``q = w Λ⁻¹ x`` (eq. 2 initial conditions, eq. 5 with ``w ∈ {0, 1}``).

    Parameters
    ----------
    x : ndarray, (..., d)
    cov : ndarray, (..., d, d) — positive definite
    weight : ndarray, (...) or None

    Returns
    -------
    P : ndarray, (..., d, d);  q : ndarray, (..., d)
    """
    info = np.linalg.inv(cov)
    P = info
    q = (info @ x[..., None])[..., 0]
    if weight is not None:
        w = np.asarray(weight, dtype=np.float64)
        P = P * w[..., None, None]
        q = q * w[..., None]
    return P, q


def ml_consensus(P0, q0, topology, rounds: int, *, history: bool = False):
    """Distributed ML of Xiao–Boyd–Lall: consensus on ``(P, q)``, ``θ_i = P_i⁻¹ q_i`` (eqs. 2–3).

    Parameters
    ----------
    P0 : ndarray, (n_nodes, ..., d, d) — ``Λ_i⁻¹`` (or 0 outside a subset, eq. 5)
    q0 : ndarray, (n_nodes, ..., d) — ``Λ_i⁻¹ x_i`` (or 0)
    topology : Topology or (E, 2) edges
    rounds : int
    history : bool — also return ``θ`` of every round, ``(rounds + 1, n_nodes, ..., d)``

    Returns
    -------
    theta : ndarray, (n_nodes, ..., d) — zeros where ``P_i`` is still singular
    P, q : ndarrays after ``rounds`` rounds; ``P_i → (1/N) Σ Λ_j⁻¹`` (eq. 3)
    ok : ndarray, (n_nodes, ...) bool — ``P_i`` invertible
    stats : CommStats — one bundle of ``d(d+1)/2 + d`` reals per extra axis element
    """
    P = np.array(P0, dtype=np.float64)
    q = np.array(q0, dtype=np.float64)
    d = q.shape[-1]
    n = P.shape[0]
    topo = as_topology(topology, n)
    per = int(np.prod(q.shape[1:-1], dtype=np.int64))
    msg = bundle_bytes(per * (d * (d + 1) // 2 + d))
    stats = CommStats()
    trace = []
    if history:
        trace.append(solve_information(P, q)[0])
    for t in range(whole_count(rounds, "rounds", 0)):
        A = topo.weights(t)
        stats.add_round(len(topo.edges(t)), msg)
        P = _mix(A, P)
        q = _mix(A, q)
        if history:
            trace.append(solve_information(P, q)[0])
    theta, ok = solve_information(P, q)
    out = (theta, P, q, ok, stats)
    if history:
        out = out + (np.stack(trace),)
    return out


# --------------------------------------------------------------------------------------------
# max-c consensus: choosing the robots of each hypothesis


def max_c_consensus(draws, topology, c: int, rounds: int, *, before_round=None):
    """Max-c consensus ``h_i(t+1) = max^c(h_i(t) ∪_{j∈N_i} h_j(t))`` (eq. 6), per hypothesis.

    Parameters
    ----------
    draws : array_like, (n_nodes, K) float
        Robot ``i``'s random number ``h_i > 0`` for each of ``K`` hypotheses; ``-inf`` for a
        node that may not generate hypotheses (it still relays).
    topology : Topology or (E, 2) edges
    c : int
        Robots per hypothesis.
    rounds : int
        ``Diam(G)`` for a fixed graph (the paper's bound); more on a switching graph.
    before_round : callable ``(t, changed) -> None`` or None
        Called at the start of round ``t`` with the nodes whose set changed in round
        ``t - 1`` (all in round 0), ``(n_nodes,)`` bool: what their messages must carry
        (:mod:`pipeline.fusion.protocol`); it may change what ``topology.edges(t)`` returns.

    Returns
    -------
    sets : ndarray, (n_nodes, K, c)
        Each node's current ``c`` largest values, descending, ``-inf`` padded.
    stats : CommStats — one message carries ``K c`` reals.

    Notes
    -----
    Vectorized over nodes with neighbour lists padded to the maximum degree of the round.
    The union of eq. (6) is a *set*: a value heard from several neighbours counts once.
    """
    h = np.asarray(draws, dtype=np.float64)
    if h.ndim != 2:
        raise InputError(f"draws must have shape (n_nodes, K), got {h.shape}")
    if c < 1:
        raise InputError(f"c must be >= 1, got {c}")
    n, K = h.shape
    topo = as_topology(topology, n)
    sets = np.full((n, K, c), -np.inf)
    sets[:, :, 0] = h
    stats = CommStats()
    msg = bundle_bytes(K * c, with_degree=False)
    changed = np.ones(n, dtype=bool)
    for t in range(whole_count(rounds, "rounds", 0)):
        if before_round is not None:
            before_round(t, changed)
        e = topo.edges(t)
        stats.add_round(len(e), msg)
        if len(e) == 0:
            changed = np.zeros(n, dtype=bool)
            continue
        src = np.concatenate([e[:, 0], e[:, 1]])  # receiver
        dst = np.concatenate([e[:, 1], e[:, 0]])  # sender
        order = np.argsort(src, kind="stable")
        src, dst = src[order], dst[order]
        deg = np.bincount(src, minlength=n)
        slot = np.arange(len(src)) - np.repeat(np.cumsum(deg) - deg, deg)
        cand = np.full((n, deg.max() + 1, K, c), -np.inf)
        cand[:, 0] = sets
        cand[src, 1 + slot] = sets[dst]
        new_sets = top_c_distinct(cand.transpose(0, 2, 1, 3).reshape(n, K, -1), c)
        changed = (new_sets != sets).any(axis=(1, 2))
        sets = new_sets
    return sets, stats


def top_c_distinct(cand: np.ndarray, c: int) -> np.ndarray:
    """The ``c`` largest *distinct* values along the last axis, descending, ``-inf`` padded:
    ``max^c`` of eq. (6) over a union of sets (a value heard twice counts once).

    Examples
    --------
    >>> top_c_distinct(np.array([[0.2, 0.9, 0.2, -np.inf]]), 2)
    array([[0.9, 0.2]])
    """
    cand = -np.sort(-np.asarray(cand, dtype=np.float64), axis=-1)
    dup = np.zeros(cand.shape, dtype=bool)
    dup[..., 1:] = cand[..., 1:] == cand[..., :-1]
    cand[dup] = -np.inf
    return -np.sort(-cand, axis=-1)[..., :c]


def hypothesis_members(draws, sets) -> np.ndarray:
    """Eq. (7): robot ``i`` is in ``V_h`` iff its own draw is among its final ``c`` values.

    Parameters
    ----------
    draws : ndarray, (n_nodes, K);  sets : ndarray, (n_nodes, K, c)

    Returns
    -------
    members : ndarray, (n_nodes, K) bool
    """
    h = np.asarray(draws, dtype=np.float64)
    return np.isfinite(h) & (sets == h[..., None]).any(-1)


# --------------------------------------------------------------------------------------------
# RANSAC


def whole_count(value, name: str, least: int) -> int:
    """``value`` as an int; InputError naming it unless a whole number >= ``least`` (a
    negative count of rounds ran none, a fractional one was truncated)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise InputError(f"{name} must be a whole number >= {least}, got {value!r}")
    return int(value)


def ransac_hypotheses(p_in: float, c: int, success: float = 0.99) -> int:
    """Number of hypotheses ``K = ⌈log(1 − p_s) / log(1 − p_in^c)⌉`` (Fischler–Bolles, ref. [5]).

    ``K`` is the smallest count for which at least one hypothesis is drawn from inliers only
    with probability ``>= success``. Sec. V: ``p_in = 0.6, c = 1, p_s = 0.99`` gives 6;
    ``p_in = 0.8`` gives 3.

    Examples
    --------
    >>> ransac_hypotheses(0.6, 1, 0.99), ransac_hypotheses(0.8, 1, 0.99)
    (6, 3)
    """
    if not 0 < p_in <= 1:
        raise InputError(f"p_in must be in (0, 1], got {p_in}")
    if not 0 < success < 1:
        raise InputError(f"success probability must be in (0, 1), got {success}")
    whole_count(c, "c (points)", 1)
    good = p_in ** c
    if good >= 1:
        return 1
    return max(1, math.ceil(math.log(1 - success) / math.log(1 - good) - 1e-12))


def ransac_success(p_in: float, c: int, K: int) -> float:
    """Probability ``1 − (1 − p_in^c)^K`` that some hypothesis holds inliers only."""
    if not 0 <= p_in <= 1:  # also refuses nan
        raise InputError(f"p_in must be in [0, 1], got {p_in}")
    whole_count(c, "c (points)", 1)
    whole_count(K, "K (hypotheses)", 0)
    return 1.0 - (1.0 - p_in ** c) ** int(K)
