"""One robot of the exact fusion mode: its flood messages and its state machine.

:class:`FloodRobot` is one robot's round of the flood of :mod:`pipeline.fusion.flooding`
(its module docstring states the algorithm and proves it): it keeps the entries it heard,
relays the new ones, closes a track's component when nothing new arrives and decides
(:func:`pipeline.fusion.decision.decide`); a lost link is flooded as a tombstone. The
message sizes (:func:`entry_bytes`, :func:`tombstone_bytes`) are those the vectorized
flood counts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.fusion.decision import Decision, decide
from pipeline.fusion.protocol import WIRE_DTYPES, index_bytes, to_wire
from pipeline.transport import HEADER_BYTES

__all__ = ["entry_bytes", "message_bytes", "tombstone_bytes", "FloodEntries", "FloodMessage",
           "FloodRobot", "robot_step"]


def entry_bytes(n: int, K: int, d: int, wire: str, estimated: bool) -> int:
    """Bytes of one entry (module docstring): id, neighbour bitmap, flags, draws and bundle."""
    size = index_bytes(n) + (n + 7) // 8 + 1
    if estimated:
        size += 8 * K + (d + d * (d + 1) // 2) * np.dtype(WIRE_DTYPES[wire]).itemsize
    return int(size)


def message_bytes(n_open, n_est, n_relay, n, K, d, wire):
    """Bytes of messages with ``n_open`` open tracks and that many entries; 0 if no track."""
    n_open = np.asarray(n_open, dtype=np.int64)
    size = (HEADER_BYTES + n_open * index_bytes(n + 1) + (n_open + 7) // 8
            + np.asarray(n_est, dtype=np.int64) * entry_bytes(n, K, d, wire, True)
            + np.asarray(n_relay, dtype=np.int64) * entry_bytes(n, K, d, wire, False))
    return np.where(n_open > 0, size, 0)


@dataclass
class FloodEntries:
    """Robots' entries of one track (what is flooded), one row per entry.

    Attributes
    ----------
    robot : ndarray, (E,) int64 — distinct robots
    neighbours : ndarray, (E, n) bool — each one's neighbours in the track's observer graph
    estimated : ndarray, (E,) bool
    draws : ndarray, (E, K) — ``-inf`` when not estimated
    x : ndarray, (E, d) — wire image (zeros when not estimated)
    info : ndarray, (E, d, d) — wire image of ``Λ⁻¹`` (zeros when not estimated)
    """

    robot: np.ndarray
    neighbours: np.ndarray
    estimated: np.ndarray
    draws: np.ndarray
    x: np.ndarray
    info: np.ndarray

    def __len__(self) -> int:
        return int(self.robot.shape[0])


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
    tracks: dict = field(default_factory=dict)   # name -> (last: bool, FloodEntries)
    down: dict = field(default_factory=dict)     # name -> [(a, b)] lost links, a < b

    def nbytes(self, n: int, K: int, d: int, wire: str) -> int:
        """Size on the wire (module docstring)."""
        n_est = sum(int(ents.estimated.sum()) for _, ents in self.tracks.values())
        n_all = sum(len(ents) for _, ents in self.tracks.values())
        size = int(message_bytes(len(self.tracks), n_est, n_all - n_est, n, K, d, wire))
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
            self._learn(s, FloodEntries(
                np.array([self.robot], dtype=np.int64), s.neighbours[None].copy(),
                np.array([est]),
                (np.asarray(tr["draws"], np.float64) if est else np.full(K, -np.inf))[None],
                (to_wire(np.asarray(tr["x"]), wire) if est else np.zeros(d))[None],
                (to_wire(np.asarray(tr["info"]), wire) if est else np.zeros((d, d)))[None]), 0)
            self.tracks[name] = s

    @staticmethod
    def _learn(s: _TrackState, e: FloodEntries, t: int) -> None:
        """Keep the entries of robots not known yet (rows of ``e`` are distinct robots)."""
        new = ~s.known[e.robot]
        if not new.any():
            return
        k = e.robot[new]
        s.known[k], s.learned[k], s.nb[k], s.est[k] = True, t, e.neighbours[new], e.estimated[new]
        s.draws[k], s.x[k], s.info[k] = e.draws[new], e.x[new], e.info[new]

    @staticmethod
    def _entries(s: _TrackState, k: np.ndarray) -> FloodEntries:
        """The held entries of robots ``k`` (copies)."""
        return FloodEntries(k, s.nb[k], s.est[k], s.draws[k], s.x[k], s.info[k])

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
                got[entries.robot] = True
                if not s.done:
                    self._learn(s, entries, t_prev)
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
            other = fresh != self.robot
            for j in np.flatnonzero(s.neighbours & ~s.gone).tolist():
                if news:
                    tomb = [e for e in news if j not in e
                            and e not in s.down_sent_by.get(j, ())]
                    if tomb:
                        out.setdefault(j, FloodMessage(self.robot, j, t)).down[name] = tomb
                if j in s.closed:
                    continue
                got = s.sent_by.get(j)
                if s.stopped:
                    send = fresh[:0]
                else:
                    # j heard its neighbours' entries in round 1, unless the link went down
                    heard = other & s.nb[j, fresh]
                    if s.down and heard.any():
                        heard[heard] = [(min(j, k), max(j, k)) not in s.down
                                        for k in fresh[heard].tolist()]
                    keep = (fresh != j) & ~heard
                    if got is not None:
                        keep &= ~got[fresh]
                    send = fresh[keep]
                again = s.resend.pop(j, None)
                if again:
                    more = sorted(k for k in again
                                  if k not in send and (got is None or not got[k]))
                    send = np.concatenate([send, np.asarray(more, dtype=np.int64)])
                if s.stopped and not send.size:
                    continue
                msg = out.setdefault(j, FloodMessage(self.robot, j, t))
                msg.tracks[name] = (bool(s.done), self._entries(s, send))
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
