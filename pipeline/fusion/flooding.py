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

The flood (:func:`flood`, one robot: :class:`~pipeline.fusion.flood_robot.FloodRobot`)
---------------------------------------------------------
Every observer ``i`` of a track has one *entry*: its id, its neighbours in the track's
observer graph, whether it formed an estimate, its ``K`` max-c draws (eq. 6) and its
observation ``(x_i, Λ_i⁻¹)`` at the wire's precision. In round 1 it sends its entry to each
neighbour; in round ``t`` it sends each neighbour ``j`` the entries it first heard in round
``t − 1``, except those ``j`` surely holds (``j``'s own, those of ``j``'s neighbours — ``j``
heard them in round 1 — and those ``j`` sent it). After ``t`` rounds robot ``i`` holds the
entries of its ``t``-ball; the ball is its whole component exactly when every neighbour list it
holds names only robots it holds (``t = ecc(i)``). It then decides (:func:`~pipeline.fusion.decision.decide`) and sends
once more, with a *last* flag, the entries it heard in that round; a neighbour stops waiting for
a robot once it received its last message. So robot ``i`` takes part in ``ecc(i) + 1`` rounds
and a track in ``Diam + 1``, the bound of max-c consensus (eq. 6) plus one. No global knowledge
is used beyond the team size ``n``: a component has at most ``n`` robots, so ``ecc ≤ n − 1``;
a robot that has not closed its ball by round ``n − 1`` after the last lost link it learned
decides on what it holds (a guard, ``settled`` false; never reached in the tests).

Crashes during the flood (tombstones; :meth:`~pipeline.fusion.flood_robot.FloodRobot.step`)
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
  (:meth:`~pipeline.fusion.flood_robot.FloodRobot.component`). It decides when every robot of its ball is known, on the
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
:func:`~pipeline.fusion.decision.decide` on the same entries (copies of the same wire images), which is deterministic
and row-independent: the same ``V_h``, ``Y_h``, winner, ``θ`` and inliers. ∎

If the crash disconnects a track's observer graph, each component decides on its own
survivors (the claim per component): a track seen on both sides of a crashed robot can then
have two fused points and two sets of cut links, each consistent within its side. A crash
after every observer of a track decided is heard of all the same while any flood still runs
(its links go down, tombstones follow) and the track is decided again without the crashed
robot; once no robot sends anything the stage is over and later crashes change nothing.
The faulty path runs the robots one by one (:func:`run_robots_on`); the vectorized
:func:`flood` is the fault-free path, tested equal to the robots.

The decision (:func:`~pipeline.fusion.decision.decide`, the same function for every robot, row by row)
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
result depends only on that row: the vectorized simulator (:func:`flood` then :func:`~pipeline.fusion.decision.decide` on
all rows at once) and the robots one by one (:class:`~pipeline.fusion.flood_robot.FloodRobot`) agree bit for bit.

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

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from pipeline.fusion.decision import Decision, decide
from pipeline.fusion.flood_robot import FloodRobot, message_bytes, robot_step
from pipeline.fusion.protocol import to_wire

__all__ = ["FloodRun", "flood", "run_robots", "run_robots_on", "exact_dynamic_voting"]


# --------------------------------------------------------------------------------------------
# the robots one by one (FloodRobot, pipeline.fusion.flood_robot)


def run_robots(robots: list, max_rounds: int | None = None):
    """Drive :class:`~pipeline.fusion.flood_robot.FloodRobot` s over a lossless network, one :func:`~pipeline.fusion.flood_robot.robot_step` each per
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
    """Drive :class:`~pipeline.fusion.flood_robot.FloodRobot` s over an exchange of the fusion stage (a faulty network's
    :class:`~pipeline.fusion.protocol.LockstepExchange`), one :meth:`~pipeline.fusion.flood_robot.FloodRobot.step` each per
    logical round.

    Each round the robots' messages are sized per directed comm link (``link_ends`` order:
    ``2 k`` first end to second, ``2 k + 1`` back) and carried by ``exchange.round``; a
    message on a link the exchange reports down is not delivered, and from the next round
    both ends are told the other is lost (``lost`` of :meth:`~pipeline.fusion.flood_robot.FloodRobot.step`). A robot the
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


@dataclass
class _Slots:
    """The observers of each track in robot order: slot ``s`` of track ``b`` is robot
    ``robot[b k + s]`` (``-1`` past its observers), ``k`` the most observers of a track;
    the node ``b n + i`` of an observer is the slot node ``node[b n + i]`` (``-1``: robot
    ``i`` does not observe track ``b``). The flood and the decisions run on slot nodes:
    their state follows the observers of each track, not the whole team."""

    n: int
    k: int
    robot: np.ndarray
    node: np.ndarray

    def node_of(self, slot_nodes) -> np.ndarray:
        """The node ``b n + i`` of slot nodes ``b k + s`` (observers only)."""
        slot_nodes = np.asarray(slot_nodes, dtype=np.int64)
        return (slot_nodes // self.k) * self.n + self.robot[slot_nodes]

    def take(self, a, fill=0):
        """``(B, n, ...)`` per robot to ``(B, k, ...)`` per slot (``fill`` past the observers)."""
        a = np.asarray(a)
        B = len(self.robot) // self.k
        flat = a.reshape((B * self.n,) + a.shape[2:])
        idx = np.arange(B * self.k) // self.k * self.n + np.maximum(self.robot, 0)
        out = flat[idx]
        out[self.robot < 0] = fill
        return out.reshape((B, self.k) + a.shape[2:])

    def edges(self, node_edges) -> np.ndarray:
        """Node edges ``(b n + i, b n + j)`` (between observers) as slot-node edges."""
        ne = np.asarray(node_edges, dtype=np.int64).reshape(-1, 2)
        return self.node[ne]


def _slots(observes) -> _Slots:
    """The :class:`_Slots` of ``observes`` ``(B, n)``."""
    observes = np.asarray(observes, dtype=bool)
    B, n = observes.shape
    count = observes.sum(1)
    k = max(int(count.max(initial=0)), 1)
    ob_b, ob_i = np.nonzero(observes)                 # by track, then robot: slots in order
    slot = np.arange(len(ob_b)) - np.repeat(np.cumsum(count) - count, count)
    robot = np.full(B * k, -1, dtype=np.int64)
    robot[ob_b * k + slot] = ob_i
    node = np.full(B * n, -1, dtype=np.int64)
    node[ob_b * n + ob_i] = ob_b * k + slot
    return _Slots(n, k, robot, node)


def flood(observes, node_edges, edge_link, n_links: int, *, estimated, K: int, d: int,
          wire: str, exchange=None) -> FloodRun:
    """The flood of every track at once; row ``b n + i`` is robot ``i``'s state in track ``b``
    (computed on the tracks' observers alone, :func:`_flood_slots`).

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
    :class:`~pipeline.fusion.flood_robot.FloodRobot` is the same update for one robot, tested equal.
    """
    observes = np.asarray(observes, dtype=bool)
    B, n = observes.shape
    sl = _slots(observes)
    run = _flood_slots(sl.take(observes, False), sl.edges(node_edges), edge_link, n_links, n,
                       estimated=sl.take(np.asarray(estimated, dtype=bool).reshape(B, n), False),
                       K=K, d=d, wire=wire, exchange=exchange)
    known = np.zeros((B * n, n), dtype=bool)
    r, c = np.nonzero(run.known)
    known[sl.node_of(r), sl.robot[(r // sl.k) * sl.k + c]] = True
    decided = np.full(B * n, -1, dtype=np.int64)
    mine = sl.robot >= 0
    decided[sl.node_of(np.flatnonzero(mine))] = run.decided_round[mine]
    return FloodRun(known=known, decided_round=decided, rounds=run.rounds, settled=run.settled,
                    sizes=run.sizes)


def _flood_slots(observes, node_edges, edge_link, n_links: int, n: int, *, estimated, K: int,
                 d: int, wire: str, exchange=None) -> FloodRun:
    """:func:`flood` on the tracks' observers alone (:class:`_Slots`): ``observes``,
    ``estimated`` ``(B, k)`` and ``node_edges`` over slot nodes ``b k + s``, ``n`` the team
    size (message sizes, round cap). The state of a node holds one column per observer of
    its track, ``O(B k²)`` for tracks of at most ``k`` observers, not ``O(B n²)``; the
    update is :func:`flood`'s, column for column (a robot that does not observe a track
    never enters its state)."""
    observes = np.asarray(observes, dtype=bool)
    B, k = observes.shape
    M = B * k
    obs = observes.reshape(-1)
    est = np.asarray(estimated, dtype=bool).reshape(B, k)
    robot = np.tile(np.arange(k), B)                  # the slot of each node
    ne = np.asarray(node_edges, dtype=np.int64).reshape(-1, 2)
    E = len(ne)
    src = np.concatenate([ne[:, 0], ne[:, 1]])
    dst = np.concatenate([ne[:, 1], ne[:, 0]])
    link2 = np.concatenate([2 * edge_link, 2 * edge_link + 1]).astype(np.int64)
    rev = np.concatenate([np.arange(E) + E, np.arange(E)])
    nbr = np.zeros((M, k), dtype=bool)
    nbr[src, robot[dst]] = True
    nbr_t = nbr.reshape(B, k, k)
    has_edge = np.zeros(M, dtype=bool)
    has_edge[src] = True
    known = np.zeros((M, k), dtype=bool)
    known[obs, robot[obs]] = True
    learned = np.where(known, 0, -1).astype(np.int64)
    gone = np.zeros((M, k), dtype=bool)
    sent = np.zeros((2 * E, k), dtype=bool)
    closed_in = np.zeros(2 * E, dtype=bool)       # the sender of this edge sent its last
    link_up = np.ones(max(int(n_links), 0), dtype=bool)
    done = obs & ~has_edge                        # an observer without neighbours knows all
    decided = np.where(done, 0, -1).astype(np.int64)
    stopped = ~obs.copy()
    dec_known = known.copy()
    forced = np.zeros(M, dtype=bool)              # decided by the cap, ball not closed
    # column s of a row: is the entry of slot s estimated? (per track)
    est_k = np.repeat(est, k, axis=0)             # (M, k): est[b, s] for row b k + i
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
        size = message_bytes(n_open, n_e.astype(np.int64), n_r.astype(np.int64), n, K, d,
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
        kt = known.reshape(B, k, k).astype(np.float64)
        reach = (kt @ nbr_t.astype(np.float64)).reshape(M, k) > 0
        closes = ~(reach & ~known & ~gone).any(1)
        now = obs & ~done & (closes | (t >= cap))
        forced |= now & ~closes
        done |= now
        decided[now] = t
        dec_known[now] = known[now]
    return FloodRun(known=dec_known, decided_round=decided, rounds=int(t_last),
                    settled=not bool(forced.any()), sizes=sizes)


def _flood_by_robots(sl: _Slots, observes, node_edges, edge_link, exchange, *, estimated,
                     draws, x, info, K: int, c: int, thr: float, wire: str) -> FloodRun:
    """The flood of every track by :class:`~pipeline.fusion.flood_robot.FloodRobot` s over ``exchange``
    (:func:`run_robots_on`), as a :class:`FloodRun` on the slot nodes of ``sl`` (``known``:
    each robot's last decision set; rows of robots that crashed before deciding: what they
    held)."""
    observes = np.asarray(observes, dtype=bool)
    B, n = observes.shape
    k = sl.k
    ne = sl.edges(node_edges)
    nbr = np.zeros((B * k, k), dtype=bool)
    nbr[ne[:, 0], ne[:, 1] % k] = nbr[ne[:, 1], ne[:, 0] % k] = True

    def neighbours(b: int, i: int) -> np.ndarray:
        row = np.zeros(n, dtype=bool)
        row[sl.robot[b * k + np.flatnonzero(nbr[sl.node[b * n + i]])]] = True
        return row

    robots = [FloodRobot(i, n, {int(b): dict(neighbours=neighbours(b, i), estimated=estimated[b, i],
                                             draws=draws[b, i], x=x[b, i], info=info[b, i])
                                for b in np.flatnonzero(observes[:, i])},
                         K=K, d=x.shape[-1], wire=wire, c=c, thr=thr) for i in range(n)]
    rounds, sizes = run_robots_on(robots, exchange.link_ends, exchange)
    known = np.zeros((B * k, k), dtype=bool)
    decided = np.full(B * k, -1, dtype=np.int64)
    forced = False
    for r in robots:
        for b, st in r.tracks.items():
            row = sl.node[b * n + r.robot]
            held = st.known_at_decision if st.known_at_decision is not None else st.known
            slots = sl.robot[b * k:(b + 1) * k]
            known[row] = held[np.maximum(slots, 0)] & (slots >= 0)
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

    # the flood and the decisions on each track's observers alone (_Slots): per track
    # O(k²) state for its k observers, not O(n²) for the team
    observes = np.asarray(observes, dtype=bool)
    sl = _slots(observes)
    k = sl.k
    if isinstance(exchange, LockstepExchange):
        # a faulty network: links can go down, so the robots run one by one with tombstones
        run = _flood_by_robots(sl, observes, node_edges, edge_link, exchange, estimated=est,
                               draws=draws, x=x, info=info, K=K, c=c, thr=thr, wire=wire)
    else:
        run = _flood_slots(sl.take(observes, False), sl.edges(node_edges), edge_link, n_links,
                           n, estimated=sl.take(est, False), K=K, d=d, wire=wire,
                           exchange=exchange)
    rows = np.flatnonzero(observes.reshape(-1))
    srows = sl.node[rows]
    tb = rows // n
    # a row's decision is a function of its track's entries and the set it holds alone
    # (decide's rows are independent): robots of one track holding the same set decide the
    # same, so each distinct (track, set) is decided once
    key = np.concatenate([tb[:, None], np.packbits(run.known[srows], axis=1)], 1)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    tf = tb[first]
    # (slots in robot order: the sums over robots add the same terms in the same order)
    dec = decide(run.known[srows[first]], sl.take(est, False)[tf], sl.take(draws, -np.inf)[tf],
                 sl.take(xw)[tf], sl.take(infow)[tf], c=c, thr=thr, team=n)
    dec = Decision(**{f: getattr(dec, f)[inv] for f in Decision.__dataclass_fields__})
    theta = np.zeros((B * n, d))
    valid = np.zeros(B * n, dtype=bool)
    inlier = np.zeros(B * n, dtype=bool)
    winner = np.zeros(B * n, dtype=np.int64)
    votes = np.zeros((B * n, K))
    members = np.zeros((B * n, K), dtype=bool)
    own = srows % k
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
