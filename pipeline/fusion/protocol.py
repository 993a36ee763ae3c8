"""The fusion stage's rounds on the robots' network: what a message carries, when the robots
stop, and how a round travels over a faulty network (Montijano et al., eqs. 2, 6, 11).

The messages and the stop rule below are those of the Metropolis mode
(``fuse_tracks(consensus="metropolis")``). The default exact mode floods each track's
observations instead (:mod:`pipeline.fusion.flooding`: its own message layout, ``Diam + 1``
rounds) and travels through the same exchanges (:class:`CountingExchange`,
:class:`LockstepExchange`).

Messages (what a link carries)
------------------------------
Robots ``i`` and ``j`` exchange, per round, one message in each direction that bundles only
the tracks *both* observe (the flat-node edges of :mod:`pipeline.fusion.landmarks` that lie on
the comm link ``(i, j)``) and, of those, only the tracks still running at the sender. Its
layout, counted byte for byte (:func:`message_bytes`):

* the transport header (:data:`pipeline.transport.HEADER_BYTES`);
* per running track: its stop counter ``c`` (below; ``uint8``, ``uint16`` when the stop
  window needs it) and one bit of a *changed* bitmap;
* per changed track: the sender's degree in the track's observer graph (for the Metropolis
  weight, ``uint8`` / ``uint16``) and its ``K`` bundles ``(P, q, v)`` of eq. (11), ``P`` as
  its ``d (d + 1) / 2`` upper-triangle entries, each real as ``float32`` (``wire="float32"``)
  or ``float64``. An unchanged track is not resent: the receiver keeps the last bundle.

Max-c consensus (eq. 6) messages are the same with the ``K c`` draws (``float64``, since the
members of eq. 7 are decided by their order) in place of the bundles and no counter.

Distributed stop rule (:func:`stop_counters`)
---------------------------------------------
Robot ``i`` of a track raises its flag in round ``t`` when its message of round ``t`` equals
that of round ``t − 1`` (nothing changed at the wire's precision) and its opinion did not
change (``u_i(t) = 0`` in eqs. 13–14). It keeps a counter
``c_i(t) = 0`` without the flag, else ``1 + min(c_i(t − 1), min_{j ∈ N_i} c_j(t − 1))``
(each neighbour's counter travels in its message), and stops when ``c_i(t) ≥ W + 1``.

Why it is correct: by induction on ``m``, ``c_i(t) ≥ m`` implies that every robot at distance
``r ≤ m − 1`` from ``i`` raised its flag in every round from ``t − m + 1`` to ``t − r``; with
``W`` at least the diameter of the track's observer graph, every observer raised it in the same
round ``t − W``. Then no observer's state changed in that round, and since the update of
eqs. (11)–(14) is a deterministic function of a robot's state and its neighbours', nothing
changes in any later round either: the robots stopped at a fixed point of eq. (11), which is
the value the consensus would hold after any number of further rounds (eq. 3 approximated to
the wire's precision). The decisions fed by it — the gate of eq. (12), the winner
``argmax_h v_i^h`` and the outlier cut — are read at that fixed point, so they are the
decisions a longer run would take. ``W`` needs no global knowledge beyond what is public: the
team size bounds any observer graph's diameter (``W = n − 1``; a robot that stops sends its
counter once more as "stopped", and a stopped robot's bundle is its last one for ever). A
consensus that does not reach a fixed point within the ``rounds`` cap stops there, as the
fixed-round scheme did. On a complete observer graph Metropolis weights average in one round,
so the stop comes ``W + 1`` rounds after the last opinion change (finite-time consensus).

Faults (:class:`LockstepExchange`)
----------------------------------
On a faulty network each logical round of max-c and of dynamic voting is carried by the
reliable channel of the consistency stage (:class:`pipeline.consistency.channel.Channel`:
sequence numbers, acknowledgements, retransmission, a neighbour silent for ``loss_timeout``
rounds while expected is declared lost) with a lockstep barrier (an α-synchronizer, as the
consistency stage's detection): robot ``i`` computes round ``t + 1`` only once it holds the
round-``t`` message of every neighbour still running a shared track. So with message loss,
delay or a switching topology (messages wait while a link is down) the logical computation is
the fault-free one, bit for bit; only network rounds and retransmissions grow. The timers
are set for the network's delay as in the consistency stage
(:meth:`~pipeline.consistency.protocols.ProtocolOptions.for_delay`). A crash is a
robot leaving the graph: once its neighbours declare it lost, the links to it leave the
consensus graph (Metropolis weights on the remaining graph, doubly stochastic again — the
switching graphs of Assumption 2.1); in the exact mode the lost links are flooded as
tombstones and every survivor decides on its connected remainder
(:mod:`pipeline.fusion.flooding`, "Crashes during the flood"). Robots crashed before the fusion stage starts take no
part in it (:func:`pipeline.stages.fusion_stage`). Network rounds are counted with a barrier at
the end of every logical round (every robot waits for the slowest), an upper bound on the
rounds an α-synchronizer needs.
"""

from __future__ import annotations

import numpy as np

from pipeline.transport import HEADER_BYTES

__all__ = ["WIRE_DTYPES", "LinkTraffic", "CountingExchange", "LockstepExchange",
           "stop_counters", "message_bytes", "bundle_reals", "to_wire", "hypothesis_draws"]

WIRE_DTYPES = {"float32": np.float32, "float64": np.float64}

_MASK64 = np.uint64(0xFFFFFFFFFFFFFFFF)


def _splitmix64(z: np.ndarray) -> np.ndarray:
    """The splitmix64 finalizer, elementwise on uint64 (wrapping arithmetic)."""
    z = (z + np.uint64(0x9E3779B97F4A7C15)) & _MASK64
    z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & _MASK64
    z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & _MASK64
    return z ^ (z >> np.uint64(31))


def hypothesis_draws(seed: int, names, robots, K: int) -> np.ndarray:
    """Max-c draws ``h_i ∈ (0, 1]`` (eq. 6) of robot ``robots[r]`` in track ``names[r]``.

    A robot draws its own numbers: each is a hash of public data only (the run's ``seed``,
    the track's name as the robots learnt it, the robot's id, the hypothesis index), so a
    robot in its own process draws exactly what the simulator draws for it, whatever other
    tracks the team holds. Uniform on the 2⁵³ doubles ``(k + 1) 2⁻⁵³``, like
    ``1 − Generator.random()``.

    Parameters
    ----------
    seed : int
    names : array_like, (R,) int — track names (``>= 0``)
    robots : array_like, (R,) int
    K : int — hypotheses

    Returns
    -------
    ndarray, (R, K) float64

    Examples
    --------
    >>> d = hypothesis_draws(0, [5, 5], [0, 1], 3)
    >>> d.shape, bool(((d > 0) & (d <= 1)).all()), bool((d[0] != d[1]).all())
    ((2, 3), True, True)
    >>> bool((hypothesis_draws(0, [5], [1], 3) == d[1]).all())
    True
    """
    names = np.asarray(names, dtype=np.int64).reshape(-1).astype(np.uint64)
    robots = np.asarray(robots, dtype=np.int64).reshape(-1).astype(np.uint64)
    z = _splitmix64(np.full(names.shape, int(seed) & 0xFFFFFFFFFFFFFFFF, dtype=np.uint64))
    z = _splitmix64(z ^ names)
    z = _splitmix64(z ^ robots)
    z = _splitmix64(z[:, None] ^ np.arange(int(K), dtype=np.uint64)[None])
    return ((z >> np.uint64(11)).astype(np.float64) + 1.0) * 2.0 ** -53


def bundle_reals(K: int, d: int) -> int:
    """Reals in one track's ``K`` bundles ``(P, q, v)``: ``K (d (d + 1) / 2 + d + 1)``."""
    return int(K) * (d * (d + 1) // 2 + d + 1)


def to_wire(a: np.ndarray, wire: str) -> np.ndarray:
    """A copy of ``a`` as it is after a trip through the wire (``float32`` rounding), float64."""
    if wire == "float64":
        return np.array(a, dtype=np.float64)
    return a.astype(WIRE_DTYPES[wire]).astype(np.float64)


def index_bytes(max_value: int) -> int:
    """Bytes of an unsigned integer field holding values up to ``max_value``."""
    return 1 if max_value < 2 ** 8 else 2 if max_value < 2 ** 16 else 4


def message_bytes(n_running, n_changed, changed_bytes: int, counter_bytes: int) -> np.ndarray:
    """Bytes of messages with ``n_running`` tracks of which ``n_changed`` carry their bundle.

    Header, a counter per running track (``counter_bytes``, 0 without counters), the changed
    bitmap, and ``changed_bytes`` per changed track. Zero where no track runs (no message).
    """
    n_running = np.asarray(n_running, dtype=np.int64)
    n_changed = np.asarray(n_changed, dtype=np.int64)
    size = (HEADER_BYTES + n_running * counter_bytes + (n_running + 7) // 8
            + n_changed * int(changed_bytes))
    return np.where(n_running > 0, size, 0)


def stop_counters(counter: np.ndarray, flag: np.ndarray, edges: np.ndarray,
                  stopped: np.ndarray) -> np.ndarray:
    """One round of the stop counters ``c_i(t)`` (module docstring), all nodes at once.

    Parameters
    ----------
    counter : ndarray, (M,) int — ``c(t − 1)``
    flag : ndarray, (M,) bool — nothing changed at the node this round
    edges : ndarray, (E, 2) int — undirected node edges in force
    stopped : ndarray, (M,) bool — nodes already stopped (their counter counts as infinite)

    Returns
    -------
    ndarray, (M,) int — ``c(t)``; row ``i`` reads only ``c_i`` and its neighbours' counters,
    which are in their messages.
    """
    big = np.iinfo(np.int64).max // 2
    prev = np.where(stopped, big, counter)
    nb = np.full(len(counter), big, dtype=np.int64)
    if len(edges):
        np.minimum.at(nb, edges[:, 0], prev[edges[:, 1]])
        np.minimum.at(nb, edges[:, 1], prev[edges[:, 0]])
    return np.where(flag, 1 + np.minimum(prev, nb), 0)


class LinkTraffic:
    """Which comm link each flat-node edge lies on, to bundle per-track traffic into messages.

    Parameters
    ----------
    node_edges : ndarray, (E, 2) int — flat-node edges ``(b n + i, b n + j)``
    edge_link : ndarray, (E,) int — comm link of each node edge
    link_ends : ndarray, (C, 2) int — robots ``(i, j)`` of each comm link; node edge ``e``
        joins ``b n + link_ends[k, 0]`` (first column) and ``b n + link_ends[k, 1]``
    """

    def __init__(self, node_edges: np.ndarray, edge_link: np.ndarray, link_ends: np.ndarray):
        self.node_edges = np.asarray(node_edges, dtype=np.int64).reshape(-1, 2)
        self.edge_link = np.asarray(edge_link, dtype=np.int64).reshape(-1)
        self.link_ends = np.asarray(link_ends, dtype=np.int64).reshape(-1, 2)
        self.n_links = len(self.link_ends)

    def directed(self, running: np.ndarray, changed: np.ndarray, alive: np.ndarray):
        """Per directed link (``2 k``: first end to second, ``2 k + 1``: back): how many
        running and changed tracks its message bundles.

        ``running``/``changed`` are per node (the sender's side); ``alive`` per node edge.
        """
        a, b = self.node_edges[:, 0], self.node_edges[:, 1]
        k2 = 2 * self.edge_link
        n2 = 2 * self.n_links
        w = alive.astype(np.int64)
        run = (np.bincount(k2, weights=w * running[a], minlength=n2)
               + np.bincount(k2 + 1, weights=w * running[b], minlength=n2))
        chg = (np.bincount(k2, weights=w * (running[a] & changed[a]), minlength=n2)
               + np.bincount(k2 + 1, weights=w * (running[b] & changed[b]), minlength=n2))
        return run.astype(np.int64), chg.astype(np.int64)

    def senders(self) -> tuple[np.ndarray, np.ndarray]:
        """Sending and receiving robot of each directed link, ``(2C,)`` each."""
        src = np.empty(2 * self.n_links, dtype=np.int64)
        dst = np.empty(2 * self.n_links, dtype=np.int64)
        src[0::2], dst[0::2] = self.link_ends[:, 0], self.link_ends[:, 1]
        src[1::2], dst[1::2] = self.link_ends[:, 1], self.link_ends[:, 0]
        return src, dst


class CountingExchange:
    """The lossless static network: every logical round is one network round; counts only.

    Attributes
    ----------
    rounds, messages, bytes : int — totals; ``by_kind`` : dict kind -> [rounds, messages, bytes]
    """

    def __init__(self, n_links: int):
        self.n_links = int(n_links)
        self.rounds = self.messages = self.bytes = 0
        self.network_rounds = 0
        self.by_kind: dict[str, list[int]] = {}
        self.retransmissions = 0
        self.dropped = 0

    def round(self, kind: str, sizes: np.ndarray) -> np.ndarray:
        """Carry one logical round; ``sizes`` (2C,) bytes per directed link (0: no message).
        Returns the comm links still in use, ``(C,)`` bool."""
        sizes = np.asarray(sizes, dtype=np.int64)
        msgs, nbytes = int((sizes > 0).sum()), int(sizes.sum())
        self.rounds += 1
        self.network_rounds += 1
        self.messages += msgs
        self.bytes += nbytes
        k = self.by_kind.setdefault(kind, [0, 0, 0])
        k[0] += 1
        k[1] += msgs
        k[2] += nbytes
        return np.ones(self.n_links, dtype=bool)

    @property
    def crashed(self) -> set:
        return set()

    def finish(self) -> None:
        """Nothing is left in flight on a lossless network."""

    def summary(self) -> dict:
        return dict(rounds=self.rounds, network_rounds=self.network_rounds,
                    messages=self.messages, bytes=self.bytes,
                    retransmissions=self.retransmissions, dropped=self.dropped,
                    by_kind={k: dict(rounds=v[0], messages=v[1], bytes=v[2])
                             for k, v in self.by_kind.items()})


class LockstepExchange(CountingExchange):
    """Logical rounds over a faulty simulated network by the reliable channel, in lockstep.

    See the module docstring. Messages are sent and counted by ``network`` (drops, delays,
    crashes and a switching topology are its options); every packet the channel adds
    (sequence numbers, acknowledgements, retransmissions) is counted too.

    Parameters
    ----------
    network : pipeline.transport.simulated.Network — over the fusion stage's robots
    link_ends : ndarray, (C, 2) int — the comm links the fusion messages travel on
    options : ProtocolOptions or None — ``retransmit_after``, ``heartbeat_every``,
        ``loss_timeout``; ``None``: those of the consistency stage with the timers set for the
        network's ``delay_rounds`` (:meth:`ProtocolOptions.for_delay`), as a deployment sets
        them from the radio's latency
    """

    def __init__(self, network, link_ends: np.ndarray, options=None):
        from pipeline.consistency.channel import Channel
        from pipeline.consistency.protocols import ProtocolOptions

        super().__init__(len(np.asarray(link_ends).reshape(-1, 2)))
        self.network = network
        self.link_ends = np.asarray(link_ends, dtype=np.int64).reshape(-1, 2)
        delay = int(getattr(getattr(network, "options", None), "delay_rounds", 0) or 0)
        self.options = options or ProtocolOptions.for_delay(delay)
        self.channels = [Channel(network.endpoint(i), self.options) for i in range(network.n)]
        self._start = (int(network.messages), int(network.bytes), int(network.dropped))
        counters = network.counters()
        self._start_by_kind = (dict(counters["messages_by_kind"]),
                               dict(counters["bytes_by_kind"]))
        self._start_round = int(network.round)
        self._link_up = np.ones(self.n_links, dtype=bool)

    @property
    def crashed(self) -> set:
        """Robots the network crashed by now (simulation side, for the report and to leave
        their observations unjudged: they never finished)."""
        return {i for i in range(self.network.n) if not self.network.alive(i)}

    @property
    def link_up(self) -> np.ndarray:
        """(C,) bool — the comm links still in use (not down since a robot crashed or an end
        declared the other lost)."""
        return self._link_up.copy()

    def _lost(self, i: int, j: int) -> bool:
        return j in self.channels[i].lost or i in self.channels[j].lost

    def _step(self, waiting: list[set], kind: str, t: int) -> None:
        """One network round: deliver, acknowledge, retransmit, time out silent neighbours."""
        net = self.network
        net.end_round()
        now = net.round
        for i, ch in enumerate(self.channels):
            if not net.alive(i):
                continue
            for m in ch.receive(net.inbox(i), now):
                if m.kind == kind and int(m.payload["t"][0]) == t:
                    waiting[i].discard(m.src)
            ch.flush(now)
            for j in ch.check_lost(now, waiting_on=waiting[i]):
                waiting[i].discard(j)

    def round(self, kind: str, sizes: np.ndarray) -> np.ndarray:
        sizes = np.asarray(sizes, dtype=np.int64)
        net = self.network
        now = net.round
        t = self.rounds
        waiting: list[set] = [set() for _ in range(net.n)]
        for k, (a, b) in enumerate(self.link_ends):
            for s, r, size in ((a, b, sizes[2 * k]), (b, a, sizes[2 * k + 1])):
                if size <= 0 or not self._link_up[k] or not net.alive(s):
                    continue
                # the payload stands for the message's content (its size is what is counted);
                # "t" names the logical round so a late duplicate is never taken for another
                self.channels[s].send(int(r), kind, {
                    "t": np.array([t], dtype=np.int32),
                    "body": np.zeros(max(int(size) - HEADER_BYTES, 0), dtype=np.uint8)}, now)
                if net.alive(r):
                    waiting[r].add(int(s))
        while any(waiting[i] for i in range(net.n) if net.alive(i)):
            self._step(waiting, kind, t)
        for k, (a, b) in enumerate(self.link_ends):
            if self._link_up[k] and (self._lost(a, b) or not net.alive(a) or not net.alive(b)):
                self._link_up[k] = False
        self.rounds += 1
        k = self.by_kind.setdefault(kind, [0, 0, 0])
        k[0] += 1
        self._sync_counts()
        return self._link_up.copy()

    def finish(self) -> None:
        """Drain: retransmit until every message is acknowledged or its receiver is lost."""
        net = self.network
        waiting: list[set] = [set() for _ in range(net.n)]
        while any(not ch.idle() for i, ch in enumerate(self.channels) if net.alive(i)):
            self._step(waiting, "", -1)
        self._sync_counts()

    def _sync_counts(self) -> None:
        net = self.network
        self.messages = int(net.messages) - self._start[0]
        self.bytes = int(net.bytes) - self._start[1]
        self.dropped = int(net.dropped) - self._start[2]
        self.network_rounds = int(net.round) - self._start_round
        self.retransmissions = sum(ch.retransmissions for ch in self.channels)

    def summary(self) -> dict:
        """As :meth:`CountingExchange.summary`; ``by_kind`` holds what the network carried
        since this exchange began, by message kind: the logical rounds' kinds (with their
        retransmissions) and the channel's own ``ack`` and ``heartbeat`` packets, so that
        they add up to ``messages`` and ``bytes``."""
        out = super().summary()
        counters = self.network.counters()
        msgs0, bytes0 = self._start_by_kind
        kinds = list(self.by_kind) + [k for k in counters["messages_by_kind"]
                                      if k not in self.by_kind]
        by_kind = {}
        for k in kinds:
            msgs = int(counters["messages_by_kind"].get(k, 0)) - int(msgs0.get(k, 0))
            nbytes = int(counters["bytes_by_kind"].get(k, 0)) - int(bytes0.get(k, 0))
            if k in self.by_kind or msgs or nbytes:
                by_kind[k] = dict(rounds=self.by_kind.get(k, [0])[0], messages=msgs,
                                  bytes=nbytes)
        out["by_kind"] = by_kind
        out["robots_lost"] = {int(i): sorted(int(j) for j in ch.lost)
                              for i, ch in enumerate(self.channels) if ch.lost}
        out["crashed"] = sorted(int(i) for i in self.crashed)
        return out
