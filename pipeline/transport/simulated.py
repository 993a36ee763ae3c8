"""The in-process simulator of the :class:`~pipeline.transport.Transport` interface.

Synchronous rounds: what a robot sends in round ``t`` is in its neighbour's inbox in round
``t + 1``. A robot may send only to its *current* communication neighbours; every message and
every byte is counted. Faults are properties of the network, never of the algorithm code:
message drop, delivery delay, crashed robots and a topology that changes per round are
switched on through :class:`NetworkOptions`. Their defaults are off (a lossless, static
network, the setting of the paper). The network only loses, delays or cuts; what the robots do
about it (acknowledgements, retransmissions, timeouts) is robot protocol, in
:mod:`pipeline.consistency.reliable`.

Delay (stated): a message is transmitted in the round it is sent, over a link up in that
round, and spends ``delay_rounds`` extra rounds in flight (what a robot sends in round ``t``
is in its neighbour's inbox in round ``t + 1 + delay_rounds``). When it is due it is delivered
if its receiver is alive: a sender that crashed meanwhile does not recall it, and a link that
went down meanwhile (switching topology) does not either, since it already left; a receiver
that crashed meanwhile never gets it (counted as dropped). :attr:`Network.lost_in_flight` and
:attr:`Network.delivered_after_sender_crash` count the two crash cases.

What a robot may know about the network (stated): its *current* neighbours, as a radio's
neighbour table would list them (:meth:`Network.links_up`: the links of the topology in force
this round, crashed robots included, because a crash cannot be seen, only inferred from
silence). Sending to a robot that is not a current neighbour is a programming error and raises
:class:`~pipeline.transport.NotANeighbourError`; the fault-tolerant protocol checks
:meth:`Network.links_up` first and keeps the message for retransmission while the link is down.

The fusion stage sends its rounds through this network too when it is faulty (lockstep over
the reliable channel, :class:`pipeline.fusion.protocol.LockstepExchange`); on a fault-free
network it counts its traffic in bulk with :meth:`Network.count`. :meth:`Network.edges` gives
the topology's links of any round (crashes and drops not applied) to vectorized code that runs
the paper's switching-graph consensus.

Byte encoding: see :mod:`pipeline.transport`.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from pipeline.commgraph import neighbour_table
from pipeline.errors import InputError
from pipeline.transport import Message, NotANeighbourError, Transport
from pipeline.validate import is_number

__all__ = ["NetworkOptions", "Network", "recurrent_topology"]


@dataclass
class NetworkOptions:
    """Fault switches of the network. All off by default (the paper's setting).

    Attributes
    ----------
    drop_probability : float
        Each message is lost with this probability (independently).
    delay_rounds : int
        Extra rounds every message spends in flight (0: delivered next round).
    crashed : frozenset of int
        Robots that neither send nor receive (their sends are discarded, counted as dropped).
    crash_at : dict ``robot -> round``
        Robots that crash at the start of the given network round (rounds count from 0 over
        the whole run, all phases); from then on they are as in ``crashed``.
    topology : callable ``round -> iterable of (i, j)`` or None
        Communication edges in force at each round; ``None`` keeps the initial edges.
    seed : int
        Seed of the drop generator.

    Notes
    -----
    The paper's algorithms are proven for the lossless static network. With any switch on,
    :func:`~pipeline.consistency.engines.driver.resolve_conflicts` has the robots run the
    fault-tolerant protocol of :mod:`pipeline.consistency.reliable` (unless told otherwise); the network itself
    only drops, delays and cuts.
    """

    drop_probability: float = 0.0
    delay_rounds: int = 0
    crashed: frozenset = field(default_factory=frozenset)
    crash_at: dict = field(default_factory=dict)
    topology: Callable[[int], Iterable[tuple[int, int]]] | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        p = self.drop_probability
        if not is_number(p) \
                or not 0.0 <= p <= 1.0:  # also refuses nan
            raise InputError(f"NetworkOptions drop_probability {p!r}: give a probability in "
                             "[0, 1]")
        for name in ("delay_rounds", "seed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise InputError(f"NetworkOptions {name} {v!r}: give a whole number >= 0")
        if self.topology is not None and not callable(self.topology):
            # failed at the network's first round with "'int' object is not callable"
            raise InputError(f"NetworkOptions topology {self.topology!r}: give a function of "
                             "the round that returns its (i, j) edges, or None")
        for r, t in dict(self.crash_at).items():
            if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or t < 0:
                raise InputError(f"NetworkOptions crash_at: robot {r!r} crashes at round {t!r}; "
                                 "give a round number >= 0")

    @property
    def any_fault(self) -> bool:
        """True when some switch is on (the network is not the paper's lossless static one)."""
        return bool(self.drop_probability > 0 or self.delay_rounds or self.crashed
                    or self.crash_at or self.topology is not None)


def recurrent_topology(comm_edges, p_up: float = 0.5, window: int = 4, seed: int = 0):
    """A topology that changes every round, each edge up at least once per ``window`` rounds.

    Every round each communication edge is up independently with probability ``p_up``; an
    edge that has been down for ``window - 1`` consecutive rounds is forced up. So the union of
    the graphs over any ``window`` consecutive rounds is the whole communication graph: if that
    graph is connected, the sequence is jointly connected over windows of ``window`` rounds
    (Assumption 2.1 of Montijano et al.), and every single edge recurs, which detection needs
    (the blocks ``X_kj`` over an association ``W_ik`` can only travel over the edge ``(i, k)``).

    Parameters
    ----------
    comm_edges : array_like, (E, 2) int
    p_up : float in (0, 1]
    window : int >= 1
    seed : int

    Returns
    -------
    callable ``round -> (E_t, 2) int64``; deterministic, repeatable for any round order.
    """
    edges = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
    window = max(1, int(window))
    cache: list[np.ndarray] = []  # up masks of rounds 0, 1, ...
    rng = np.random.default_rng(seed)
    down_for = np.zeros(len(edges), dtype=np.int64)

    def topology(t: int) -> np.ndarray:
        nonlocal down_for
        while len(cache) <= t:
            up = (rng.random(len(edges)) < p_up) | (down_for >= window - 1)
            down_for = np.where(up, 0, down_for + 1)
            cache.append(up)
        return edges[cache[int(t)]]

    topology.window = window
    return topology



def _check_crashed_robots(options: NetworkOptions, n: int) -> None:
    """InputError naming a robot of ``crashed`` / ``crash_at`` outside ``0..n-1``."""
    for name, robots in (("crashed", options.crashed), ("crash_at", options.crash_at)):
        for r in robots:
            if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 0 <= r < n:
                raise InputError(f"NetworkOptions {name}: robot {r!r} does not exist; the team's "
                                 f"robots are 0..{n - 1}" if n else
                                 f"NetworkOptions {name}: robot {r!r} does not exist; the team "
                                 "has no robot")


class Network(Transport):
    """Synchronous message passing between neighbouring robots, simulated in process.

    Parameters
    ----------
    n : int
        Number of robots.
    comm_edges : array_like, (E, 2) int
        Undirected communication edges ``(i, j)``.
    options : NetworkOptions or None
    keyed_drops : bool
        Decide each message's drop from ``(seed, sender, receiver, round, its number among
        that sender's messages to that receiver in that round)`` alone, and deliver a round's
        messages sender by sender (each sender's in its send order), instead of drawing the
        drops from one generator in send order. Robots that send from threads of their own
        (:class:`~pipeline.transport.local.LocalTeam`) send in an order no one chooses; keyed,
        the same seed drops the same messages and fills the same inboxes whatever that order.
        Off by default: a driver that sends in a fixed order keeps its drop draws.

    Notes
    -----
    Usage per round: each robot reads ``inbox(i)`` and calls ``send``; then the driver calls
    :meth:`end_round`, which moves the sent messages to the inboxes of the next round (or of
    ``delay_rounds`` rounds later).

    Attributes
    ----------
    messages, bytes, dropped : int — sent messages and bytes; messages lost (drop, crash)
    lost_in_flight : int — messages whose receiver crashed while they were in flight
    delivered_after_sender_crash : int — messages delivered after their sender crashed
    """

    def __init__(self, n: int, comm_edges, options: NetworkOptions | None = None, *,
                 keyed_drops: bool = False) -> None:
        self.n = int(n)
        self.options = options or NetworkOptions()
        self.keyed_drops = bool(keyed_drops)
        # keyed drops: (src, dst) -> (round, messages sent on that link in that round so far)
        self._link_sent: dict[tuple[int, int], tuple[int, int]] = {}
        _check_crashed_robots(self.options, self.n)
        self._initial_edges = [tuple(map(int, e)) for e in np.asarray(comm_edges).reshape(-1, 2)]
        self._nbrs = neighbour_table(self._initial_edges, self.n)
        self._round = 0
        self._peak_memory = [0] * self.n
        # delivery round -> messages due then, in send order: a round touches only its own
        # (with a delay of D rounds, D rounds of traffic are in flight at once)
        self._outbox: dict[int, list[Message]] = {}
        self._inboxes: list[list[Message]] = [[] for _ in range(self.n)]
        self._filled: list[int] = []  # robots whose inbox holds messages, in delivery order
        self._rng = np.random.default_rng(self.options.seed)
        self.messages = 0
        self.bytes = 0
        self.dropped = 0
        self.lost_in_flight = 0
        self.delivered_after_sender_crash = 0
        self.messages_by_kind: dict[str, int] = {}
        self.bytes_by_kind: dict[str, int] = {}
        self._apply_topology()

    # --- topology -------------------------------------------------------------------------
    @property
    def round(self) -> int:
        return self._round

    def _apply_topology(self) -> None:
        if self.options.topology is not None:
            self._nbrs = neighbour_table(self._topology_edges(self.round), self.n)

    def _topology_edges(self, t: int) -> np.ndarray:
        """The edges ``options.topology`` gives for round ``t``, ``(E, 2)`` int64; InputError
        when they are no pairs of this team's robots (an IndexError deep in the neighbour
        table, or a robot ``-1`` read as the last one)."""
        given = self.options.topology(t)
        try:
            e = np.asarray(given, dtype=np.int64).reshape(-1, 2)
        except (TypeError, ValueError):
            raise InputError(f"NetworkOptions topology: round {t} gives {given!r}; give pairs "
                             "(i, j) of robot ids") from None
        bad = np.flatnonzero(((e < 0) | (e >= self.n)).any(axis=1))
        if bad.size:
            raise InputError(f"NetworkOptions topology: round {t} gives edge "
                             f"{tuple(e[bad[0]].tolist())}, which names a robot outside the "
                             f"team's 0..{self.n - 1}")
        return e

    def edges(self, t: int) -> np.ndarray:
        """Links of the topology in round ``t``, ``(E_t, 2)`` int64 (crashes not applied)."""
        if self.options.topology is None:
            return np.asarray(self._initial_edges, dtype=np.int64).reshape(-1, 2)
        return self._topology_edges(t)

    @property
    def switching(self) -> bool:
        return self.options.topology is not None

    @property
    def window(self) -> int:
        """The topology's recurrence window (:func:`recurrent_topology` states it), else 1."""
        return int(getattr(self.options.topology, "window", 1))

    @property
    def faulty(self) -> bool:
        return self.options.any_fault

    def neighbours(self, i: int) -> frozenset:
        """Current communication neighbours of robot ``i`` (a crashed robot has none)."""
        if not self.alive(i):
            return frozenset()
        return frozenset(j for j in self._nbrs[i] if self.alive(j))

    def alive(self, i: int) -> bool:
        """False once robot ``i`` has crashed (simulation side; robots cannot call this)."""
        opts = self.options
        if i in opts.crashed:
            return False
        at = opts.crash_at.get(i)
        return at is None or self.round < int(at)

    def links_up(self, i: int) -> frozenset:
        """Robot ``i``'s neighbour table this round: the topology's links, crashes unseen."""
        return frozenset(self._nbrs[i])

    def is_neighbour(self, i: int, j: int) -> bool:
        return j in self._nbrs[i]

    # --- messages -------------------------------------------------------------------------
    def send(self, src: int, dst: int, kind: str, payload: dict) -> None:
        """Queue a message from ``src`` to its current neighbour ``dst``.

        Raises
        ------
        NotANeighbourError
            ``dst`` is not a current communication neighbour of ``src``.
        """
        if dst not in self._nbrs[src]:
            raise NotANeighbourError(
                f"robot {src} tried to send a {kind!r} message to robot {dst}, "
                f"which is not its neighbour in round {self.round}")
        msg = Message(int(src), int(dst), kind, payload, self.round)
        size = msg.nbytes
        self.messages += 1
        self.bytes += size
        self.messages_by_kind[kind] = self.messages_by_kind.get(kind, 0) + 1
        self.bytes_by_kind[kind] = self.bytes_by_kind.get(kind, 0) + size
        opts = self.options
        if not self.alive(src) or not self.alive(dst):
            self.dropped += 1
            return
        if opts.drop_probability > 0.0 and self._draw(msg) < opts.drop_probability:
            self.dropped += 1
            return
        self._outbox.setdefault(self.round + 1 + int(opts.delay_rounds), []).append(msg)

    def _draw(self, msg: Message) -> float:
        """The uniform draw in [0, 1) that decides whether ``msg`` is dropped."""
        if not self.keyed_drops:
            return float(self._rng.random())
        link = (msg.src, msg.dst)
        t, k = self._link_sent.get(link, (self.round, 0))
        k = k if t == self.round else 0
        self._link_sent[link] = (self.round, k + 1)
        key = struct.pack("<5Q", int(self.options.seed), msg.src, msg.dst, self.round, k)
        return int.from_bytes(hashlib.blake2b(key, digest_size=8).digest(), "little") / 2.0**64

    def inbox(self, i: int) -> list[Message]:
        """Messages delivered to robot ``i`` at the start of the current round."""
        return self._inboxes[i]

    def receivers(self) -> list[int]:
        """Robots with a message delivered this round, ascending (simulation side)."""
        return sorted(self._filled)

    def end_round(self) -> None:
        """Close the round: advance the clock and deliver what is due."""
        self._round += 1
        self._apply_topology()
        due = self._outbox.pop(self.round, [])
        if self.keyed_drops:
            due.sort(key=lambda m: m.src)  # stable: each sender's messages in its send order
        # fresh lists for the inboxes that held messages (a caller may keep the old one);
        # the others are empty already: a round with little traffic costs what it carries
        for i in self._filled:
            self._inboxes[i] = []
        self._filled = []
        for m in due:
            if self.alive(m.dst):
                box = self._inboxes[m.dst]
                if not box:
                    self._filled.append(m.dst)
                box.append(m)
                self.delivered_after_sender_crash += not self.alive(m.src)
            else:
                self.dropped += 1
                self.lost_in_flight += 1

    @property
    def in_flight(self) -> bool:
        """True while some message is queued or sits undelivered in an inbox."""
        return bool(self._outbox) or bool(self._filled)

    @property
    def pending(self) -> bool:
        """True while some sent message has not been delivered yet."""
        return bool(self._outbox)

    def injected_faults(self) -> dict:
        """The fault switches: drop probability, switching topology, crash round per robot."""
        opts = self.options
        crash_rounds = {int(i): 0 for i in opts.crashed}
        crash_rounds.update({int(i): int(r) for i, r in opts.crash_at.items()})
        return dict(drop_probability=float(opts.drop_probability),
                    switching_topology=opts.topology is not None, crash_rounds=crash_rounds)

    def count(self, kind: str, messages: int, nbytes: int) -> None:
        """Count ``messages`` exchanged in bulk, ``nbytes`` in all, under ``kind``."""
        self.messages += int(messages)
        self.bytes += int(nbytes)
        self.messages_by_kind[kind] = self.messages_by_kind.get(kind, 0) + int(messages)
        self.bytes_by_kind[kind] = self.bytes_by_kind.get(kind, 0) + int(nbytes)

    def note_memory(self, i: int, nbytes: int) -> None:
        self._peak_memory[i] = max(self._peak_memory[i], int(nbytes))

    def peak_memory(self, i: int) -> int:
        return self._peak_memory[i]

    def counters(self) -> dict:
        """Message and byte counters so far."""
        return dict(messages=self.messages, bytes=self.bytes, dropped=self.dropped, round=self.round,
                    messages_by_kind=dict(self.messages_by_kind),
                    bytes_by_kind=dict(self.bytes_by_kind))
