"""Exact dynamic voting: each track's observations flooded over its observer graph, then the
consensus limit computed locally (Montijano et al., eqs. 1–3, 6–7, 10–14; finite-time consensus).

Why it is exact
---------------
The dynamic voting of Sec. IV-B runs the average consensus of eq. (2) — Metropolis weights on
each track's observer graph — with the inputs ``u_i`` of eqs. (13)–(14). ``A(t)`` is doubly
stochastic, so the sums ``Σ_i P_i(t)``, ``Σ_i q_i(t)``, ``Σ_i v_i(t)`` of a connected observer
graph change only by the inputs: they always equal the sums of ``(Λ_j⁻¹, Λ_j⁻¹ x_j, 1)`` over the
robots ``Y(t)`` whose current opinion is yes (eqs. 5, 10 at ``t = 0``). When the opinions
settle, ``P_i → (1/N) Σ_Y Λ_j⁻¹``, ``θ_i → θ_ML(Y)`` (eqs. 1, 3), ``v_i → |Y| / N`` and ``Y`` is a
fixed point of the gate map

    ``F(S) = {j : d(x_j, θ_ML(S), Λ_j) ≤ χ²}``   (eq. 12 at the limit of eq. 11).

The paper's iteration approaches that limit asymptotically (a ring needs hundreds of rounds to
settle to float precision). Here every robot learns its component's observations and computes
it: it holds the limit after ``Diam + 1`` rounds, with no stop threshold and no round cap.

Why it is the default: it is the paper's estimator read at its limit, in ``Diam + 1`` rounds
and a few bytes per observer (each entry crosses each link at most once in each direction), with no round cap to
tune and no decision left to round-off. Measured (``bench/fusion.py``, formations a–d under
both resolutions and Sceaux): it cuts what the paper's Metropolis iteration cuts once that has
settled — the links where the 100-round scheme differs are vote ties or votes not settled at
100 rounds — in 2–4 rounds instead of 105, with 180–330x fewer bytes.

The flood (:func:`flood`, one robot: :class:`FloodRobot`)
---------------------------------------------------------
Every observer ``i`` of a track has one *entry*: its id, its neighbours in the track's
observer graph, whether it formed an estimate, its ``K`` max-c draws (eq. 6) and its
observation ``(x_i, Λ_i⁻¹)`` at the wire's precision. In round 1 it sends its entry to each
neighbour; in round ``t`` it sends each neighbour ``j`` the entries it first heard in round
``t − 1``, except those ``j`` surely holds (``j``'s own, those of ``j``'s neighbours — ``j``
heard them in round 1 — and those ``j`` sent it). After ``t`` rounds robot ``i`` holds the
entries of its ``t``-ball; the ball is its whole component exactly when every neighbour list it
holds names only robots it holds (``t = ecc(i)``). It then decides (:func:`decide`) and sends
once more, with a *last* flag, the entries it heard in that round; a neighbour stops waiting for
a robot once it received its last message. So robot ``i`` takes part in ``ecc(i) + 1`` rounds
and a track in ``Diam + 1``, the bound of max-c consensus (eq. 6) plus one. No global knowledge
is used beyond the team size ``n``: a component has at most ``n`` robots, so ``ecc ≤ n − 1``;
a robot that has not closed its ball by round ``n − 1`` after the last lost link it learned
decides on what it holds (a guard, ``settled`` false; never reached in the tests).

Crashes during the flood (tombstones; :meth:`FloodRobot.step`)
-------------------------------------------------------------
On a faulty network (:class:`~pipeline.fusion.protocol.LockstepExchange`) a comm link goes
down for good when a robot at one end crashes or one end declares the other lost (the
reliable channel's timeout); both ends are told (``lost``). Without more, a robot whose
entry never arrived makes robots farther away wait until the guard, and robots of one track
could decide on different sets. So:

* a robot told that its link to neighbour ``j`` is down floods a *tombstone* ``(i, j)`` on
  every track the two share: each robot passes a tombstone it learns, once, to each live
  neighbour in the track (stopped or not; not to the link's ends, nor back to its senders);
* the *ball* of robot ``i`` is the set it reaches from itself over the links it knows — the
  neighbour lists of the entries it holds — with the links it holds tombstones of removed
  (:meth:`FloodRobot.component`). It decides when every robot of its ball is known, on the
  entries of its ball. A crashed robot's entry, even if held, is in no ball once the
  tombstones of its links arrived: *a crashed robot does not vote*;
* a tombstone learned after the decision shrinks the ball; the robot then decides again on
  the smaller ball (``revisions``), so every decision reflects every crash it heard of;
* an entry is not sent to a neighbour that heard it in round 1 (the entry's robot is that
  neighbour's neighbour) only while their link is up; once it is down the entry is sent again.

Claim: when the flood has ended, the surviving observers of a track that are connected over
live links (a component ``A`` of the track's observer graph without the crashed robots and
the down links) all decide on the entries of exactly ``A``, hence identically.
Proof, in the lockstep model (a message between live robots over an up link arrives in its
logical round; a down link stays down and both ends are told):
(1) Every robot of ``A`` gets every entry of ``A``. Along a path ``k = p_0, …, p_m`` in ``A``
(its links up throughout), ``p_{l−1}`` passes ``k``'s entry to ``p_l`` the round after it first
holds it unless ``p_l`` surely holds it: its own, sent by ``p_l``, or ``k`` a neighbour of
``p_l`` over a link that is up — then ``p_l`` heard it in round 1. If that link went down, the
entry is sent again (also by a robot that stopped). (2) Every robot of ``A`` learns every down
link with an end in ``A``: that end is told, floods the tombstone, and tombstones cross ``A``'s
links as entries do, stopped robots included. (3) Every link of the observer graph from ``A``
to a robot outside ``A`` is down (the outside robot crashed — all its links go down — or the
link itself was lost), so by (1)–(2) the ball of any ``i ∈ A`` is ``A``, all known: ``i``
closes on ``A``. Before that, a ball only contains ``A`` (links inside ``A`` are never down,
and closing requires every robot reached to be known, so by induction along paths all of
``A`` was known when ``i`` first decided); later tombstones only remove robots outside ``A``,
and each one makes ``i`` decide again. So the last decision of every robot of ``A`` is
:func:`decide` on the same entries (copies of the same wire images), which is deterministic
and row-independent: the same ``V_h``, ``Y_h``, winner, ``θ`` and inliers. ∎

If the crash disconnects a track's observer graph, each component decides on its own
survivors (the claim per component): a track seen on both sides of a crashed robot can then
have two fused points and two sets of cut links, each consistent within its side. A crash
after every observer of a track decided is heard of all the same while any flood still runs
(its links go down, tombstones follow) and the track is decided again without the crashed
robot; once no robot sends anything the stage is over and later crashes change nothing.
The faulty path runs the robots one by one (:func:`run_robots_on`); the vectorized
:func:`flood` is the fault-free path, tested equal to the robots.

The decision (:func:`decide`, the same function for every robot, row by row)
---------------------------------------------------------------------------
From the entries of its component a robot computes

* the hypotheses: the ``c`` largest distinct draws of the component, which max-c consensus
  (eq. 6) holds after ``Diam`` rounds; eq. (7) then gives the same ``V_h`` as the paper;
* for each hypothesis the fixed point of ``F`` reached from ``S_0 = V_h``:
  ``S_{k+1} = F(S_k)`` until ``S_{k+1} = S_k``. This is the paper's iteration when the
  consensus has mixed fully between opinion changes (on a complete observer graph Metropolis
  weights average in one round: the two then differ only by the one-round lag with which a
  robot's own input enters its estimate). On a slowly mixing graph the paper's robots decide on
  partially mixed estimates and may settle on another fixed point of ``F``; both are fixed
  points of the same map. A set that comes back after two or more steps (a cycle of ``F``,
  where the paper's opinions would oscillate for ever) ends the iteration at the cycle's set
  with the most robots (the earliest on ties), counted in ``cycles``;
* votes as exact integer counts ``|Y_h|`` (``v_i^h = |Y_h| / N``): the winner is the
  hypothesis with the most yes-votes, ties to the lowest hypothesis index — an explicit rule,
  so neither the wire precision nor a summation order can flip a cut;
* ``θ = θ_ML(Y_{h*})`` (eq. 1) and robot ``i`` an inlier iff ``i ∈ Y_{h*}``.

Every sum over robots runs in robot-id order and every small product is written out, so a row's
result depends only on that row: the vectorized simulator (:func:`flood` then :func:`decide` on
all rows at once) and the robots one by one (:class:`FloodRobot`) agree bit for bit.

Messages
--------
Per directed comm link and round one message bundles the tracks still open on it (the sender
runs the track and the receiver has not sent its last): per open track an entry count
(``uint8``/``uint16``) and one bit of a *last* bitmap, then the entries. An entry is the robot
id (``uint8``/``uint16``), its neighbour bitmap (``⌈n / 8⌉`` bytes), a flags byte and, if the
robot formed an estimate, ``K`` draws (float64: the members of eq. 7 are decided by their
order) and ``x_i``, ``Λ_i⁻¹`` (``d + d (d + 1) / 2`` reals at the wire's precision). The
transport header is :data:`pipeline.transport.HEADER_BYTES`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from pipeline.fusion.consensus import solve_information
from pipeline.fusion.protocol import WIRE_DTYPES, index_bytes, to_wire
from pipeline.transport import HEADER_BYTES

__all__ = ["Decision", "decide", "entry_bytes", "tombstone_bytes", "FloodEntry", "FloodMessage",
           "FloodRobot", "FloodRun", "flood", "robot_step", "run_robots", "run_robots_on",
           "exact_dynamic_voting"]


# --------------------------------------------------------------------------------------------
# the decision at the consensus limit


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


def decide(known, estimated, draws, x, info, *, c: int, thr: float) -> Decision:
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

    Returns
    -------
    Decision

    Notes
    -----
    Rows are independent: entries outside ``known`` are masked to zero before use, sums over
    robots run in id order. Cost ``O(R K n d² I)`` with ``I`` the iterations of ``F`` (a few).
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
    for _ in range(4 * n + 4):
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


# --------------------------------------------------------------------------------------------
# message sizes


def entry_bytes(n: int, K: int, d: int, wire: str, estimated: bool) -> int:
    """Bytes of one entry (module docstring): id, neighbour bitmap, flags, draws and bundle."""
    size = index_bytes(n) + (n + 7) // 8 + 1
    if estimated:
        size += 8 * K + (d + d * (d + 1) // 2) * np.dtype(WIRE_DTYPES[wire]).itemsize
    return int(size)


def _message_bytes(n_open, n_est, n_relay, n, K, d, wire):
    """Bytes of messages with ``n_open`` open tracks and that many entries; 0 if no track."""
    n_open = np.asarray(n_open, dtype=np.int64)
    size = (HEADER_BYTES + n_open * index_bytes(n + 1) + (n_open + 7) // 8
            + np.asarray(n_est, dtype=np.int64) * entry_bytes(n, K, d, wire, True)
            + np.asarray(n_relay, dtype=np.int64) * entry_bytes(n, K, d, wire, False))
    return np.where(n_open > 0, size, 0)


# --------------------------------------------------------------------------------------------
# one robot


@dataclass
class FloodEntry:
    """One robot's entry of one track (what is flooded).

    Attributes
    ----------
    robot : int
    neighbours : ndarray, (n,) bool — its neighbours in the track's observer graph
    estimated : bool
    draws : ndarray, (K,) — ``-inf`` when not estimated
    x : ndarray, (d,) — wire image (zeros when not estimated)
    info : ndarray, (d, d) — wire image of ``Λ⁻¹`` (zeros when not estimated)
    """

    robot: int
    neighbours: np.ndarray
    estimated: bool
    draws: np.ndarray
    x: np.ndarray
    info: np.ndarray


def tombstone_bytes(n: int, n_tombstones: int) -> int:
    """Bytes of a message's tombstone section: a record count (``uint32``) and per record the
    track's position among the link's shared tracks (``uint32``) and the two robot ids of the
    lost link; 0 without tombstones (fault-free messages carry no such section)."""
    if not n_tombstones:
        return 0
    return int(4 + int(n_tombstones) * (4 + 2 * index_bytes(n)))


@dataclass
class FloodMessage:
    """One message of a logical round from ``src`` to ``dst``: per open track (by name) its
    *last* flag and its entries; per track with news of lost links, its tombstones."""

    src: int
    dst: int
    round: int
    tracks: dict = field(default_factory=dict)   # name -> (last: bool, [FloodEntry])
    down: dict = field(default_factory=dict)     # name -> [(a, b)] lost links, a < b

    def nbytes(self, n: int, K: int, d: int, wire: str) -> int:
        """Size on the wire (module docstring)."""
        n_est = sum(e.estimated for _, ents in self.tracks.values() for e in ents)
        n_all = sum(len(ents) for _, ents in self.tracks.values())
        size = int(_message_bytes(len(self.tracks), n_est, n_all - n_est, n, K, d, wire))
        n_tomb = sum(len(v) for v in self.down.values())
        if n_tomb:
            size = (size or HEADER_BYTES) + tombstone_bytes(n, n_tomb)
        return size


@dataclass
class _TrackState:
    neighbours: np.ndarray          # (n,) bool, own neighbours in the track
    known: np.ndarray               # (n,) bool
    learned: np.ndarray             # (n,) int, round first heard (-1: not yet)
    nb: np.ndarray                  # (n, n) bool, neighbour lists held
    est: np.ndarray                 # (n,) bool
    draws: np.ndarray               # (n, K)
    x: np.ndarray                   # (n, d)
    info: np.ndarray                # (n, d, d)
    sent_by: dict                   # neighbour -> (n,) bool entries it sent me
    closed: set                     # neighbours that sent their last message
    gone: np.ndarray                # (n,) bool, neighbours declared lost
    down: dict = field(default_factory=dict)          # lost link (a, b), a < b -> round learned
    down_sent_by: dict = field(default_factory=dict)  # neighbour -> set of links it sent me
    resend: dict = field(default_factory=dict)        # neighbour -> entries to send it again
    last_down: int = 0              # round the latest lost link was learned
    done: bool = False
    stopped: bool = False
    decided_round: int = -1
    known_at_decision: np.ndarray | None = None
    revisions: int = 0              # decisions taken again after a lost link shrank the set
    forced: bool = False            # decided by the round cap, ball not closed


class FloodRobot:
    """One robot's exact fusion: its own state and, per logical round, :meth:`step`.

    Parameters
    ----------
    robot : int — its id in ``0..n-1``
    n : int — team size (public)
    tracks : dict name -> dict(neighbours=(n,) bool, estimated=bool, draws=(K,), x=(d,),
        info=(d, d)) — the tracks it observes: its neighbours in each track's observer graph
        (from the fusion setup message) and its own observation
    K, d : int
    wire : ``"float32"`` or ``"float64"`` — precision of ``x`` and ``Λ⁻¹`` in entries
    c : int, thr : float — see :func:`decide`
    """

    def __init__(self, robot: int, n: int, tracks: dict, *, K: int, d: int, wire: str,
                 c: int, thr: float):
        self.robot, self.n, self.K, self.d, self.wire = int(robot), int(n), int(K), int(d), wire
        self.c, self.thr = int(c), float(thr)
        self.round = 0
        self.tracks: dict = {}
        self.decisions: dict = {}
        for name, tr in tracks.items():
            s = _TrackState(
                neighbours=np.asarray(tr["neighbours"], dtype=bool).copy(),
                known=np.zeros(n, dtype=bool), learned=np.full(n, -1, dtype=np.int64),
                nb=np.zeros((n, n), dtype=bool), est=np.zeros(n, dtype=bool),
                draws=np.full((n, K), -np.inf), x=np.zeros((n, d)), info=np.zeros((n, d, d)),
                sent_by={}, closed=set(), gone=np.zeros(n, dtype=bool))
            est = bool(tr["estimated"])
            self._learn(s, FloodEntry(self.robot, s.neighbours, est,
                                      np.asarray(tr["draws"], np.float64) if est
                                      else np.full(K, -np.inf),
                                      to_wire(np.asarray(tr["x"]), wire) if est else np.zeros(d),
                                      to_wire(np.asarray(tr["info"]), wire) if est
                                      else np.zeros((d, d))), 0)
            self.tracks[name] = s

    @staticmethod
    def _learn(s: _TrackState, e: FloodEntry, t: int) -> bool:
        if s.known[e.robot]:
            return False
        k = e.robot
        s.known[k], s.learned[k], s.nb[k], s.est[k] = True, t, e.neighbours, e.estimated
        s.draws[k], s.x[k], s.info[k] = e.draws, e.x, e.info
        return True

    def _entry(self, s: _TrackState, k: int) -> FloodEntry:
        return FloodEntry(int(k), s.nb[k].copy(), bool(s.est[k]), s.draws[k].copy(),
                          s.x[k].copy(), s.info[k].copy())

    @property
    def finished(self) -> bool:
        """Every track stopped: the robot sends nothing more."""
        return all(s.stopped for s in self.tracks.values())

    def component(self, name) -> np.ndarray:
        """The robots this robot reaches in track ``name`` over the links it holds (from the
        neighbour lists of the entries it holds), lost links removed; (n,) bool.

        The ball is *closed* when every robot of it is known; the decision is taken on it
        (module docstring, "Crashes during the flood").
        """
        s = self.tracks[name]
        if not s.down and not (s.nb[s.known].any(0) & ~s.known).any():
            return s.known.copy()       # no lost link and the ball closed: it is what it holds
        adj = s.nb | s.nb.T
        for a, b in s.down:
            adj[a, b] = adj[b, a] = False
        reach = np.zeros(self.n, dtype=bool)
        reach[self.robot] = True
        front = reach.copy()
        while front.any():
            nxt = adj[front].any(0) & ~reach
            reach |= nxt
            front = nxt & s.known        # an unknown robot's own links are not known yet
        return reach

    def _lose(self, s: _TrackState, a: int, b: int, t: int) -> None:
        """Take in the lost link ``(a, b)`` at round ``t``: a tombstone to pass on, and the
        entries this robot kept from a neighbour at one end because that neighbour heard the
        other end in round 1 (no longer sure) are sent to it again."""
        e = (min(a, b), max(a, b))
        if e in s.down:
            return
        s.down[e] = t
        s.last_down = t
        for j, k in ((e[0], e[1]), (e[1], e[0])):
            if j != self.robot and s.neighbours[j] and s.known[k] and k != self.robot:
                got = s.sent_by.get(j)
                if got is None or not got[k]:
                    s.resend.setdefault(j, set()).add(k)

    def _decide(self, names: list, masks: list) -> None:
        rows = [self.tracks[k] for k in names]
        dec = decide(np.stack(masks), np.stack([s.est for s in rows]),
                     np.stack([s.draws for s in rows]), np.stack([s.x for s in rows]),
                     np.stack([s.info for s in rows]), c=self.c, thr=self.thr)
        for r, name in enumerate(names):
            self.decisions[name] = Decision(
                members=dec.members[r], yes=dec.yes[r], counts=dec.counts[r],
                size=dec.size[r], winner=dec.winner[r], theta=dec.theta[r],
                valid=dec.valid[r], cycles=dec.cycles[r])

    def step(self, inbox: list, lost=()) -> list:
        """One logical round: take in the messages of the last round, decide the tracks whose
        component is now complete, and return this round's messages.

        Parameters
        ----------
        inbox : list of FloodMessage — received in round ``self.round`` (empty before round 1)
        lost : iterable of int — neighbours the network declared lost (by now; giving one
            again changes nothing)

        Returns
        -------
        list of FloodMessage — to send in round ``self.round + 1`` (after the call,
        ``self.round`` is that round)
        """
        t_prev = self.round
        lost = set(int(j) for j in lost)
        for msg in inbox:
            for name, (last, entries) in msg.tracks.items():
                s = self.tracks[name]
                got = s.sent_by.setdefault(msg.src, np.zeros(self.n, dtype=bool))
                for e in entries:
                    got[e.robot] = True
                    if not s.done:
                        self._learn(s, e, t_prev)
                if last:
                    s.closed.add(msg.src)
            for name, links in getattr(msg, "down", {}).items():
                s = self.tracks[name]
                s.down_sent_by.setdefault(msg.src, set()).update(links)
                for a, b in links:
                    self._lose(s, int(a), int(b), t_prev)
        decide_now, masks, again, again_masks = [], [], [], []
        for name, s in self.tracks.items():
            for j in lost:
                if s.neighbours[j]:
                    s.gone[j] = True
                    s.closed.add(j)
                    self._lose(s, self.robot, j, t_prev)
            fresh_down = s.last_down == t_prev and bool(s.down)
            if s.done and not fresh_down:
                continue
            comp = self.component(name)
            closed = not (comp & ~s.known).any()
            if s.done:
                # a lost link learned after the decision: decide again on what is left
                keep = comp & s.known
                s.forced = s.forced and not closed
                if not np.array_equal(keep, s.known_at_decision):
                    s.known_at_decision, s.decided_round = keep, t_prev
                    s.revisions += 1
                    again.append(name)
                    again_masks.append(keep)
                continue
            if closed or t_prev >= self.n - 1 + s.last_down:
                s.done, s.decided_round, s.forced = True, t_prev, not closed
                s.known_at_decision = comp & s.known
                decide_now.append(name)
                masks.append(s.known_at_decision)
        if decide_now:
            self._decide(decide_now, masks)
        if again:
            self._decide(again, again_masks)
        t = t_prev + 1
        out: dict[int, FloodMessage] = {}
        for name, s in self.tracks.items():
            news = [e for e, r in s.down.items() if r == t - 1]
            if s.stopped and not news and not s.resend:
                continue
            fresh = np.flatnonzero(s.learned == t - 1)
            for j in np.flatnonzero(s.neighbours & ~s.gone):
                j = int(j)
                tomb = [e for e in news if j not in e
                        and e not in s.down_sent_by.get(j, ())]
                if tomb:
                    out.setdefault(j, FloodMessage(self.robot, j, t)).down[name] = tomb
                if j in s.closed:
                    continue
                got = s.sent_by.get(j, np.zeros(self.n, dtype=bool))
                # j heard its neighbours' entries in round 1, unless the link went down
                send = [] if s.stopped else [
                    k for k in fresh if k != j and not got[k]
                    and not (k != self.robot and s.nb[j, k]
                             and (min(j, k), max(j, k)) not in s.down)]
                send += sorted(k for k in s.resend.pop(j, ()) if k not in send and not got[k])
                if s.stopped and not send:
                    continue
                msg = out.setdefault(j, FloodMessage(self.robot, j, t))
                msg.tracks[name] = (bool(s.done), [self._entry(s, k) for k in send])
            s.resend.clear()
            if s.done:
                s.stopped = True
        self.round = t
        return list(out.values())


def robot_step(state: FloodRobot, inbox: list, lost=()) -> tuple[FloodRobot, list]:
    """One robot's logical round as a function: ``(state, inbox) -> (new state, outbox)``.

    What a robot process calls once per round (:meth:`FloodRobot.step` on a copy, so
    ``state`` is left as it was): ``inbox`` are the :class:`FloodMessage` s it received in
    the round ``state.round``, ``lost`` the neighbours its channel declared lost; the outbox
    is what it sends in round ``state.round + 1``. Decisions of the tracks it closed are in
    ``new.decisions``.
    """
    import copy

    new = copy.deepcopy(state)
    return new, new.step(inbox, lost)


def run_robots(robots: list, max_rounds: int | None = None):
    """Drive :class:`FloodRobot` s over a lossless network, one :func:`robot_step` each per
    round (``robots`` is updated in place with the new states). Returns ``(rounds, sizes)`` with
    ``sizes`` a list per round of ``{(src, dst): bytes}`` (rounds in which no message was sent
    are not counted)."""
    inbox: dict[int, list] = {r.robot: [] for r in robots}
    sizes = []
    cap = max_rounds if max_rounds is not None else 2 * max(r.n for r in robots) + 2
    for _ in range(cap):
        if all(r.finished and not inbox[r.robot] for r in robots):
            break
        nxt: dict[int, list] = {r.robot: [] for r in robots}
        this = {}
        for k, r in enumerate(robots):
            if r.finished and not inbox[r.robot]:
                continue
            robots[k], outbox = robot_step(r, inbox[r.robot])
            for m in outbox:
                nxt[m.dst].append(m)
                this[(m.src, m.dst)] = m.nbytes(r.n, r.K, r.d, r.wire)
        if this:
            sizes.append(this)
        inbox = nxt
    return len(sizes), sizes


def run_robots_on(robots: list, link_ends, exchange, max_rounds: int | None = None):
    """Drive :class:`FloodRobot` s over an exchange of the fusion stage (a faulty network's
    :class:`~pipeline.fusion.protocol.LockstepExchange`), one :meth:`FloodRobot.step` each per
    logical round.

    Each round the robots' messages are sized per directed comm link (``link_ends`` order:
    ``2 k`` first end to second, ``2 k + 1`` back) and carried by ``exchange.round``; a
    message on a link the exchange reports down is not delivered, and from the next round
    both ends are told the other is lost (``lost`` of :meth:`FloodRobot.step`). A robot the
    network crashed takes no more steps. Ends when a round sends nothing.

    Parameters
    ----------
    robots : list of FloodRobot — updated in place
    link_ends : ndarray, (C, 2) int — the comm links
    exchange : CountingExchange or LockstepExchange
    max_rounds : int or None — a guard (default ``(C + 2)(n + 1)``: each lost link can
        delay a closure by at most ``n - 1`` rounds)

    Returns
    -------
    (rounds, sizes) — logical rounds in which a message was sent, and per such round the
    bytes per directed comm link, ``(2C,)``
    """
    ends = np.asarray(link_ends, dtype=np.int64).reshape(-1, 2)
    index = {}
    for k, (a, b) in enumerate(ends):
        index[(int(a), int(b))], index[(int(b), int(a))] = 2 * k, 2 * k + 1
    n = max(r.n for r in robots) if robots else 0
    by_id = {r.robot: k for k, r in enumerate(robots)}
    inbox: dict[int, list] = {r.robot: [] for r in robots}
    lost: dict[int, set] = {r.robot: set() for r in robots}
    told: dict[int, int] = {r.robot: 0 for r in robots}
    link_up = np.ones(len(ends), dtype=bool)
    sizes = []
    cap = max_rounds if max_rounds is not None else (len(ends) + 2) * (n + 1)
    for _ in range(cap):
        crashed = exchange.crashed
        size = np.zeros(2 * len(ends), dtype=np.int64)
        sent = []
        for i, k in by_id.items():
            r = robots[k]
            if i in crashed or (r.finished and not inbox[i] and told[i] == len(lost[i])):
                continue
            told[i] = len(lost[i])
            outbox = r.step(inbox[i], sorted(lost[i]))
            inbox[i] = []
            for m in outbox:
                e = index[(m.src, m.dst)]
                size[e] = m.nbytes(r.n, r.K, r.d, r.wire)
                sent.append((e, m))
        if not sent:
            break
        sizes.append(size)
        up = np.asarray(exchange.round("fusion", size), dtype=bool)
        for k in np.flatnonzero(link_up & ~up):
            a, b = int(ends[k, 0]), int(ends[k, 1])
            if a in lost:
                lost[a].add(b)
            if b in lost:
                lost[b].add(a)
        link_up &= up
        for e, m in sent:
            if link_up[e // 2] and m.dst in inbox:
                inbox[m.dst].append(m)
    return len(sizes), sizes


# --------------------------------------------------------------------------------------------
# all robots at once (the simulator)


@dataclass
class FloodRun:
    """Result of :func:`flood` over all tracks' observers.

    Attributes
    ----------
    known : ndarray, (M, n) bool — the entries each node held when it decided
    decided_round : ndarray, (M,) int — round after which it decided (-1: not an observer)
    rounds : int — logical rounds in which a message was sent
    settled : bool — every observer closed its ball (no decision forced by the cap)
    sizes : list of ndarray (2C,) — bytes per directed comm link, per round
    """

    known: np.ndarray
    decided_round: np.ndarray
    rounds: int
    settled: bool
    sizes: list


def flood(observes, node_edges, edge_link, n_links: int, *, estimated, K: int, d: int,
          wire: str, exchange=None) -> FloodRun:
    """The flood of every track at once; row ``b n + i`` is robot ``i``'s state in track ``b``.

    Parameters
    ----------
    observes : ndarray, (B, n) bool — robot ``i`` observes track ``b``
    node_edges : ndarray, (E, 2) int — flat-node edges ``(b n + i, b n + j)``; comm link
        ``edge_link[e]`` joins ``i`` (first column) and ``j``
    edge_link : ndarray, (E,) int
    n_links : int — comm links ``C``
    estimated : ndarray, (B, n) bool — whose entry carries an observation
    K, d, wire : entry layout (:func:`entry_bytes`)
    exchange : CountingExchange or None — carries every round. (A faulty network's
        :class:`~pipeline.fusion.protocol.LockstepExchange` goes through the robots,
        :func:`run_robots_on`, which handle lost links with tombstones; here a link reported
        down only marks its far end as gone for the robot at the near end.)

    Returns
    -------
    FloodRun

    Notes
    -----
    Each row is updated from its own state and the entries on its in-edges only (its inbox);
    :class:`FloodRobot` is the same update for one robot, tested equal.
    """
    observes = np.asarray(observes, dtype=bool)
    B, n = observes.shape
    M = B * n
    obs = observes.reshape(-1)
    est = np.asarray(estimated, dtype=bool).reshape(B, n)
    robot = np.tile(np.arange(n), B)
    ne = np.asarray(node_edges, dtype=np.int64).reshape(-1, 2)
    E = len(ne)
    src = np.concatenate([ne[:, 0], ne[:, 1]])
    dst = np.concatenate([ne[:, 1], ne[:, 0]])
    link2 = np.concatenate([2 * edge_link, 2 * edge_link + 1]).astype(np.int64)
    rev = np.concatenate([np.arange(E) + E, np.arange(E)])
    nbr = np.zeros((M, n), dtype=bool)
    nbr[src, robot[dst]] = True
    nbr_t = nbr.reshape(B, n, n)
    has_edge = np.zeros(M, dtype=bool)
    has_edge[src] = True
    known = np.zeros((M, n), dtype=bool)
    known[obs, robot[obs]] = True
    learned = np.where(known, 0, -1).astype(np.int64)
    gone = np.zeros((M, n), dtype=bool)
    sent = np.zeros((2 * E, n), dtype=bool)
    closed_in = np.zeros(2 * E, dtype=bool)       # the sender of this edge sent its last
    link_up = np.ones(max(int(n_links), 0), dtype=bool)
    done = obs & ~has_edge                        # an observer without neighbours knows all
    decided = np.where(done, 0, -1).astype(np.int64)
    stopped = ~obs.copy()
    dec_known = known.copy()
    forced = np.zeros(M, dtype=bool)              # decided by the cap, ball not closed
    # column k of a row: is entry k estimated? (per track)
    est_k = np.repeat(est, n, axis=0)             # (M, n): est[b, k] for row b n + i
    incidence = sp.csr_matrix((np.ones(2 * E), (dst, np.arange(2 * E))), shape=(M, 2 * E))
    rows = np.arange(2 * E)
    sizes, t_last, t = [], 0, 0
    cap = n - 1
    while not stopped.all():
        t += 1
        active = ~stopped[src] & ~closed_in[rev] & link_up[link2 // 2]
        ent = (learned[src] == t - 1) & active[:, None]
        ent[rows, robot[dst]] = False                              # its own entry
        ent &= ~sent[rev]                                          # it sent us
        nr = nbr[dst].copy()
        nr[rows, robot[src]] = False
        ent &= ~nr                                                 # it heard it in round 1
        last = done[src] & active
        n_open = np.bincount(link2[active], minlength=2 * n_links)
        n_e = np.bincount(link2, weights=(ent & est_k[src]).sum(1), minlength=2 * n_links)
        n_r = np.bincount(link2, weights=(ent & ~est_k[src]).sum(1), minlength=2 * n_links)
        size = _message_bytes(n_open, n_e.astype(np.int64), n_r.astype(np.int64), n, K, d,
                              wire)
        if active.any():
            t_last = t
            sizes.append(size)
            if exchange is not None:
                up = np.asarray(exchange.round("fusion", size), dtype=bool)
                link_up &= up
        deliver = active & link_up[link2 // 2]
        sent |= ent
        heard = (incidence @ (ent & deliver[:, None]).astype(np.float64)) > 0
        new = heard & ~known & ~done[:, None]
        learned[new] = t
        known |= new
        closed_in |= last & deliver
        down = ~link_up[link2 // 2]
        closed_in |= down
        gone[dst[down], robot[src[down]]] = True
        stopped |= done                            # a done robot sent its last this round
        kt = known.reshape(B, n, n).astype(np.float64)
        reach = (kt @ nbr_t.astype(np.float64)).reshape(M, n) > 0
        closes = ~(reach & ~known & ~gone).any(1)
        now = obs & ~done & (closes | (t >= cap))
        forced |= now & ~closes
        done |= now
        decided[now] = t
        dec_known[now] = known[now]
    return FloodRun(known=dec_known, decided_round=decided, rounds=int(t_last),
                    settled=not bool(forced.any()), sizes=sizes)


def _flood_by_robots(observes, node_edges, edge_link, exchange, *, estimated, draws, x, info,
                     K: int, c: int, thr: float, wire: str) -> FloodRun:
    """The flood of every track by :class:`FloodRobot` s over ``exchange``
    (:func:`run_robots_on`), as a :class:`FloodRun` (``known``: each robot's last decision
    set; rows of robots that crashed before deciding: what they held)."""
    observes = np.asarray(observes, dtype=bool)
    B, n = observes.shape
    ne = np.asarray(node_edges, dtype=np.int64).reshape(-1, 2)
    nbr = np.zeros((B * n, n), dtype=bool)
    nbr[ne[:, 0], ne[:, 1] % n] = nbr[ne[:, 1], ne[:, 0] % n] = True
    robots = [FloodRobot(i, n, {int(b): dict(neighbours=nbr[b * n + i], estimated=estimated[b, i],
                                             draws=draws[b, i], x=x[b, i], info=info[b, i])
                                for b in np.flatnonzero(observes[:, i])},
                         K=K, d=x.shape[-1], wire=wire, c=c, thr=thr) for i in range(n)]
    rounds, sizes = run_robots_on(robots, exchange.link_ends, exchange)
    known = np.zeros((B * n, n), dtype=bool)
    decided = np.full(B * n, -1, dtype=np.int64)
    forced = False
    for r in robots:
        for b, st in r.tracks.items():
            row = b * n + r.robot
            known[row] = st.known_at_decision if st.known_at_decision is not None else st.known
            decided[row] = st.decided_round
            forced |= st.forced and r.robot not in exchange.crashed
    return FloodRun(known=known, decided_round=decided, rounds=int(rounds),
                    settled=not forced, sizes=sizes)


# --------------------------------------------------------------------------------------------
# the fusion stage's entry point


def exact_dynamic_voting(x, cov, estimated, observes, node_edges, edge_link, n_links: int, *,
                         K: int, c: int, thr: float, rng=None, wire: str = "float32",
                         exchange=None, draws=None):
    """Dynamic voting at its consensus limit, by flooding (module docstring).

    Parameters
    ----------
    x : ndarray, (B, n, d) — each robot's observation of each track
    cov : ndarray, (B, n, d, d) — its covariance (any positive definite matrix where not
        ``estimated``)
    estimated : ndarray, (B, n) bool — the robot has an observation (it votes and may be drawn)
    observes : ndarray, (B, n) bool — the robot takes part in the track (relays at least)
    node_edges, edge_link, n_links : the observer graphs on the comm links (:func:`flood`)
    K, c : int — hypotheses and robots per hypothesis
    thr : float — gate on the squared Mahalanobis distance
    rng : seed or Generator — the max-c draws, drawn as
        :func:`pipeline.fusion.voting.choose_hypotheses` draws them (same seed, same ``V_h``)
    wire : ``"float32"`` or ``"float64"`` — precision of ``x`` and ``Λ⁻¹`` in the entries
    exchange : CountingExchange / LockstepExchange or None — carries every round
    draws : ndarray, (B, n, K) or None — each robot's own draws
        (:func:`pipeline.fusion.protocol.hypothesis_draws`) instead of ``rng``'s

    Returns
    -------
    VotingResult — ``votes`` are ``|Y_h| / N`` (exact counts over the component's size),
    ``stats.rounds`` the flood's rounds, ``maxc_stats`` empty (max-c is part of the flood)
    """
    from pipeline.fusion.consensus import CommStats
    from pipeline.fusion.voting import VotingResult, information_matrix

    x = np.asarray(x, dtype=np.float64)
    B, n, d = x.shape
    est = np.asarray(estimated, dtype=bool) & np.asarray(observes, dtype=bool)
    if draws is None:
        draws = 1.0 - np.random.default_rng(rng).random((B * n, K))   # h_i in (0, 1], eq. (6)
    else:  # each robot's own draws (pipeline.fusion.protocol.hypothesis_draws)
        draws = np.array(draws, dtype=np.float64).reshape(B * n, K)
    draws[~est.reshape(-1)] = -np.inf
    draws = draws.reshape(B, n, K)
    xw = to_wire(np.where(est[..., None], x, 0.0), wire)
    # exactly symmetric, so the upper triangle an entry carries on the wire is all of it
    info = information_matrix(np.where(est[..., None, None], cov, np.eye(d)))
    infow = to_wire(np.where(est[..., None, None], info, 0.0), wire)
    from pipeline.fusion.protocol import LockstepExchange

    if isinstance(exchange, LockstepExchange):
        # a faulty network: links can go down, so the robots run one by one with tombstones
        run = _flood_by_robots(observes, node_edges, edge_link, exchange, estimated=est,
                               draws=draws, x=x, info=info, K=K, c=c, thr=thr, wire=wire)
    else:
        run = flood(observes, node_edges, edge_link, n_links, estimated=est, K=K, d=d,
                    wire=wire, exchange=exchange)
    rows = np.flatnonzero(np.asarray(observes, dtype=bool).reshape(-1))
    tb = rows // n
    # a row's decision is a function of its track's entries and the set it holds alone
    # (decide's rows are independent): robots of one track holding the same set decide the
    # same, so each distinct (track, set) is decided once
    key = np.concatenate([tb[:, None], np.packbits(run.known[rows], axis=1)], 1)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    tf = tb[first]
    dec = decide(run.known[rows[first]], est[tf], draws[tf], xw[tf], infow[tf], c=c, thr=thr)
    dec = Decision(**{f: getattr(dec, f)[inv] for f in Decision.__dataclass_fields__})
    theta = np.zeros((B * n, d))
    valid = np.zeros(B * n, dtype=bool)
    inlier = np.zeros(B * n, dtype=bool)
    winner = np.zeros(B * n, dtype=np.int64)
    votes = np.zeros((B * n, K))
    members = np.zeros((B * n, K), dtype=bool)
    own = rows % n
    theta[rows], valid[rows], winner[rows] = dec.theta, dec.valid, dec.winner
    inlier[rows] = dec.yes[np.arange(len(rows)), dec.winner, own] & dec.valid
    votes[rows] = dec.counts / np.maximum(dec.size, 1)[:, None]
    members[rows] = dec.members[np.arange(len(rows)), own]
    stats = CommStats(rounds=run.rounds)
    res = VotingResult(theta=theta.reshape(B, n, d), valid=valid.reshape(B, n),
                       inlier=inlier.reshape(B, n), winner=winner.reshape(B, n),
                       votes=votes.reshape(B, n, K), members=members.reshape(B, n, K),
                       stats=stats, maxc_stats=CommStats(), settled=run.settled,
                       cycles=int(dec.cycles.any(1).sum()))
    return res
