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
    """One message of a logical round from ``src`` to ``dst``: its open tracks (names, each
    with its *last* flag and its entry count) and their entries, track after track; per track
    with news of lost links, its tombstones."""

    src: int
    dst: int
    round: int
    names: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))   # (T,) open tracks
    last: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))        # (T,)
    count: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))   # (T,) entries each
    entries: FloodEntries | None = None                  # (Σ count,) rows, track after track
    down: dict = field(default_factory=dict)             # name -> [(a, b)] lost links, a < b

    @property
    def tracks(self) -> dict:
        """``name -> (last, FloodEntries)`` of the open tracks (a reader's view)."""
        ends = np.cumsum(self.count)
        e = self.entries
        return {int(b): (bool(lb), FloodEntries(e.robot[a:z], e.neighbours[a:z], e.estimated[a:z],
                                                 e.draws[a:z], e.x[a:z], e.info[a:z]))
                for b, lb, a, z in zip(self.names.tolist(), self.last.tolist(),
                                       (ends - self.count).tolist(), ends.tolist(), strict=True)}

    def nbytes(self, n: int, K: int, d: int, wire: str) -> int:
        """Size on the wire (module docstring)."""
        n_all = 0 if self.entries is None else len(self.entries)
        n_est = 0 if self.entries is None else int(self.entries.estimated.sum())
        size = int(message_bytes(len(self.names), n_est, n_all - n_est, n, K, d, wire))
        n_tomb = sum(len(v) for v in self.down.values())
        if n_tomb:
            size = (size or HEADER_BYTES) + tombstone_bytes(n, n_tomb)
        return size


class _TrackView:
    """What a robot holds about one of its tracks (read-only view of its rows)."""

    def __init__(self, robot: FloodRobot, b: int):
        self._r, self._b = robot, b

    def __getattr__(self, key):
        value = getattr(self._r, "_" + key)[self._b]
        if key == "known_at_decision" and not self._r._done[self._b]:
            return None
        return value.copy() if isinstance(value, np.ndarray) else value.item() \
            if isinstance(value, np.generic) else value


class FloodRobot:
    """One robot's exact fusion: its own state and, per logical round, :meth:`step`.

    The state of all its tracks is held in arrays with one row per track (in name order), so
    a round takes in, decides and relays every track at once; the tracks touched by lost
    links (tombstones, entries sent again) are handled track by track.

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
        self.decisions: dict = {}
        names = sorted(int(b) for b in tracks)
        B = len(names)
        self.names = np.asarray(names, dtype=np.int64)
        self._neighbours = np.zeros((B, n), dtype=bool)
        self._known = np.zeros((B, n), dtype=bool)
        self._learned = np.full((B, n), -1, dtype=np.int64)
        self._nb = np.zeros((B, n, (n + 7) // 8), dtype=np.uint8)  # [b, k]: k's neighbours, packed
        self._est = np.zeros((B, n), dtype=bool)
        self._draws = np.full((B, n, K), -np.inf)
        self._x = np.zeros((B, n, d))
        self._info = np.zeros((B, n, d, d))
        self._got = None                                # [b, col(j), k]: neighbour j sent k's entry
        self._closed = np.zeros((B, n), dtype=bool)     # neighbours that sent their last
        self._gone = np.zeros((B, n), dtype=bool)       # neighbours declared lost
        self._down = [{} for _ in range(B)]             # lost link (a, b), a < b -> round learned
        self._down_sent_by = [{} for _ in range(B)]     # neighbour -> set of links it sent me
        self._resend: dict = {}                         # row -> {neighbour: entries to send again}
        self._last_down = np.zeros(B, dtype=np.int64)   # round the latest lost link was learned
        self._done = np.zeros(B, dtype=bool)
        self._stopped = np.zeros(B, dtype=bool)
        self._decided_round = np.full(B, -1, dtype=np.int64)
        self._known_at_decision = np.zeros((B, n), dtype=bool)
        self._revisions = np.zeros(B, dtype=np.int64)  # decisions taken again (a lost link)
        self._forced = np.zeros(B, dtype=bool)         # decided by the round cap, ball not closed
        i = self.robot
        for b, name in enumerate(names):
            tr = tracks[name]
            est = bool(tr["estimated"])
            self._neighbours[b] = np.asarray(tr["neighbours"], dtype=bool)
            self._est[b, i] = est
            if est:
                self._draws[b, i] = np.asarray(tr["draws"], np.float64)
                self._x[b, i] = to_wire(np.asarray(tr["x"]), wire)
                self._info[b, i] = to_wire(np.asarray(tr["info"]), wire)
        self._known[:, i] = True
        self._learned[:, i] = 0
        self._nb[:, i] = np.packbits(self._neighbours, axis=-1)
        # one column of _got per robot that is a neighbour in some track (robot order)
        self._cols = np.flatnonzero(self._neighbours.any(0))
        self._got = np.zeros((B, len(self._cols), n), dtype=bool)

    def _col(self, j: int) -> int:
        """Column of neighbour ``j`` in ``_got`` (a column is added for a sender that is a
        neighbour in none of the robot's tracks)."""
        c = int(np.searchsorted(self._cols, j))
        if c == len(self._cols) or self._cols[c] != j:
            self._cols = np.insert(self._cols, c, j)
            self._got = np.insert(self._got, c, False, axis=1)
        return c

    @property
    def tracks(self) -> dict:
        """``name -> view`` of what the robot holds about each track (``known``, ``learned``,
        ``decided_round``, ``known_at_decision``, ``forced``, ``revisions``, ...)."""
        return {int(name): _TrackView(self, b) for b, name in enumerate(self.names.tolist())}

    def _rows(self, names) -> np.ndarray:
        """Rows of the tracks ``names`` (KeyError for a track the robot does not observe)."""
        names = np.asarray(names, dtype=np.int64).reshape(-1)
        if names.size and not self.names.size:
            raise KeyError(int(names[0]))
        b = np.minimum(np.searchsorted(self.names, names), max(self.names.size - 1, 0))
        bad = np.flatnonzero(self.names[b] != names) if names.size else ()
        if len(bad):
            raise KeyError(int(names[bad[0]]))
        return b

    @property
    def finished(self) -> bool:
        """Every track stopped: the robot sends nothing more."""
        return bool(self._stopped.all())

    def component(self, name) -> np.ndarray:
        """The robots this robot reaches in track ``name`` over the links it holds (from the
        neighbour lists of the entries it holds), lost links removed; (n,) bool.

        The ball is *closed* when every robot of it is known; the decision is taken on it
        (module docstring, "Crashes during the flood").
        """
        return self._components(self._rows([name]))[0]

    def _components(self, rows: np.ndarray) -> np.ndarray:
        """:meth:`component` of the tracks ``rows``, (R, n) bool.

        Only the robots it knows and those they name as neighbours have links it holds, so
        the search of each track runs on those robots (at most the track's observers)."""
        n = self.n
        known, nbp = self._known[rows], self._nb[rows]
        out = known.copy()
        rr, kk = np.nonzero(known)
        heard = np.zeros(nbp.shape[::2], dtype=np.uint8)
        np.bitwise_or.at(heard, rr, nbp[rr, kk])
        heard_of = np.unpackbits(heard, axis=-1, count=n).astype(bool)
        down = np.array([bool(self._down[b]) for b in rows.tolist()], dtype=bool)
        # no lost link and the ball closed: it is what it holds
        slow = np.flatnonzero(down | (heard_of & ~known).any(1))
        for r in slow.tolist():
            kn = known[r]
            U = np.flatnonzero(kn | heard_of[r])             # robots with links it holds
            kU = kn[U]
            nb = np.zeros((U.size, U.size), dtype=bool)
            nb[kU] = np.unpackbits(nbp[r, U[kU]], axis=-1, count=n).astype(bool)[:, U]
            adj = nb | nb.T
            for a, z in self._down[int(rows[r])]:
                pa, pz = np.searchsorted(U, a), np.searchsorted(U, z)
                if pa < U.size and pz < U.size and U[pa] == a and U[pz] == z:
                    adj[pa, pz] = adj[pz, pa] = False
            reach = U == self.robot
            front = reach.copy()
            while front.any():
                nxt = adj[front].any(0) & ~reach
                reach |= nxt
                front = nxt & kU     # an unknown robot's own links are not known yet
            out[r] = False
            out[r, U] = reach
        return out

    def _lose(self, b: int, a: int, z: int, t: int) -> None:
        """Take in the lost link ``(a, z)`` of track row ``b`` at round ``t``: a tombstone to
        pass on, and the entries this robot kept from a neighbour at one end because that
        neighbour heard the other end in round 1 (no longer sure) are sent to it again."""
        e = (min(a, z), max(a, z))
        if e in self._down[b]:
            return
        self._down[b][e] = t
        self._last_down[b] = t
        for j, k in ((e[0], e[1]), (e[1], e[0])):
            if j != self.robot and self._neighbours[b, j] and self._known[b, k] \
                    and k != self.robot and not self._got[b, self._col(j), k]:
                self._resend.setdefault(b, {}).setdefault(j, set()).add(k)

    def _decide(self, rows: np.ndarray, masks: np.ndarray) -> None:
        dec = decide(masks, self._est[rows], self._draws[rows], self._x[rows], self._info[rows],
                     c=self.c, thr=self.thr)
        for r, name in enumerate(self.names[rows].tolist()):
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
        n = self.n
        lost = set(int(j) for j in lost)
        for msg in inbox:
            if len(msg.names):
                rows = self._rows(msg.names)
                e = msg.entries
                er = np.repeat(rows, msg.count)
                self._got[er, self._col(msg.src), e.robot] = True
                new = ~self._done[er] & ~self._known[er, e.robot]
                if new.any():
                    b, k = er[new], e.robot[new]
                    self._known[b, k], self._learned[b, k] = True, t_prev
                    self._nb[b, k] = np.packbits(e.neighbours[new], axis=-1)
                    self._est[b, k] = e.estimated[new]
                    self._draws[b, k], self._x[b, k] = e.draws[new], e.x[new]
                    self._info[b, k] = e.info[new]
                self._closed[rows[msg.last], msg.src] = True
            for name, links in getattr(msg, "down", {}).items():
                b = int(self._rows([name])[0])
                self._down_sent_by[b].setdefault(msg.src, set()).update(links)
                for a, z in links:
                    self._lose(b, int(a), int(z), t_prev)
        for j in lost:
            for b in np.flatnonzero(self._neighbours[:, j]).tolist():
                self._gone[b, j] = self._closed[b, j] = True
                self._lose(b, self.robot, j, t_prev)
        has_down = np.array([bool(d) for d in self._down], dtype=bool)
        fresh_down = has_down & (self._last_down == t_prev)
        rows = np.flatnonzero(~self._done | fresh_down)
        comp = self._components(rows)
        known = self._known[rows]
        closed = ~(comp & ~known).any(1)
        # a lost link learned after the decision: decide again on what is left
        again = []
        for r in np.flatnonzero(self._done[rows]).tolist():
            b = int(rows[r])
            keep = comp[r] & known[r]
            self._forced[b] = self._forced[b] and not closed[r]
            if not np.array_equal(keep, self._known_at_decision[b]):
                self._known_at_decision[b], self._decided_round[b] = keep, t_prev
                self._revisions[b] += 1
                again.append(b)
        now = ~self._done[rows] & (closed | (t_prev >= n - 1 + self._last_down[rows]))
        go = rows[now]
        self._done[go], self._decided_round[go], self._forced[go] = True, t_prev, ~closed[now]
        self._known_at_decision[go] = comp[now] & known[now]
        if go.size:
            self._decide(go, self._known_at_decision[go])
        if again:
            again = np.asarray(again, dtype=np.int64)
            self._decide(again, self._known_at_decision[again])
        return self._send(t_prev + 1, has_down)

    def _send(self, t: int, has_down: np.ndarray) -> list:
        """This round's messages (round ``t``), then every decided track stops."""
        n = self.n
        news = {}
        for b in np.flatnonzero(has_down).tolist():
            fresh_links = [e for e, r in self._down[b].items() if r == t - 1]
            if fresh_links:
                news[b] = fresh_links
        busy = ~self._stopped
        for b in (*news, *self._resend):
            busy[b] = True
        fresh = self._learned == t - 1
        others = np.arange(n) != self.robot
        out: dict[int, FloodMessage] = {}
        for j in np.flatnonzero((self._neighbours & busy[:, None]).any(0)).tolist():
            rows = np.flatnonzero(busy & self._neighbours[:, j] & ~self._gone[:, j])
            for b in rows.tolist():
                tomb = [e for e in news.get(b, ()) if j not in e
                        and e not in self._down_sent_by[b].get(j, ())]
                if tomb:
                    out.setdefault(j, FloodMessage(self.robot, j, t)).down[int(self.names[b])] = tomb
            rows = rows[~self._closed[rows, j]]
            if rows.size == 0:
                continue
            stopped = self._stopped[rows]
            # j heard its neighbours' entries in round 1, unless the link went down
            heard = others & np.unpackbits(self._nb[rows, j], axis=-1, count=n).astype(bool)
            for r in np.flatnonzero(has_down[rows] & heard.any(1)).tolist():
                down = self._down[rows[r]]
                for k in np.flatnonzero(heard[r]).tolist():
                    heard[r, k] = (min(j, k), max(j, k)) not in down
            got = self._got[rows, self._col(j), :]
            send = fresh[rows] & ~heard & ~got & ~stopped[:, None]
            send[:, j] = False
            r_e, k_e = np.nonzero(send)
            extra_r, extra_k = [], []
            for r in (range(rows.size) if self._resend else ()):
                more = self._resend.get(int(rows[r]), {}).pop(j, ())
                more = sorted(k for k in more if not send[r, k] and not got[r, k])
                extra_r += [r] * len(more)
                extra_k += more
            if extra_r:
                order = np.argsort(np.concatenate([r_e, extra_r]), kind="stable")
                r_e = np.concatenate([r_e, extra_r]).astype(np.int64)[order]
                k_e = np.concatenate([k_e, extra_k]).astype(np.int64)[order]
            count = np.bincount(r_e, minlength=rows.size)
            keep = ~stopped | (count > 0)
            if not keep.any():
                continue
            msg = out.setdefault(j, FloodMessage(self.robot, j, t))
            b_e = rows[r_e]
            msg.names, msg.last = self.names[rows[keep]], self._done[rows[keep]].copy()
            msg.count = count[keep].astype(np.int64)
            msg.entries = FloodEntries(k_e.astype(np.int64),
                                       np.unpackbits(self._nb[b_e, k_e], axis=-1,
                                                     count=n).astype(bool), self._est[b_e, k_e],
                                       self._draws[b_e, k_e], self._x[b_e, k_e],
                                       self._info[b_e, k_e])
        self._resend.clear()
        self._stopped |= self._done
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
