"""The transport robots talk through: the one interface of every robot-to-robot message.

docs/DESIGN.md, "the one rule": robot code sees only its own state and its inbox; all exchange goes
through a transport with synchronous rounds, ``send`` only to current neighbours, every
message and byte counted, per-robot memory measured, and faults (drop, delay, crash, a
topology that changes per round) as properties of the network, never of the algorithm code.

* :class:`Transport` — the team's network, as the driver sees it (the round clock, the
  barrier, the counters). :class:`~pipeline.transport.simulated.Network` is its in-process
  simulator; a middleware with the robots as separate processes implements the same methods.
* :class:`Endpoint` — one robot's view of it: ``send`` to a neighbour, its ``inbox`` of the
  current round, its neighbour table, the round number, its memory report. Robot-side code
  (the consistency protocols) sends only through an endpoint.
* :class:`Message` — one packet and its size on the wire.
* :class:`RoundEndpoint` — an :class:`Endpoint` with no driver behind it: a robot running as
  its own program closes each round itself (:meth:`RoundEndpoint.end_round`), and the round
  carries a small *round state* to the neighbours (the termination wave of
  :mod:`pipeline.consistency.termination`). Implementations: the robots as threads over the
  simulator (:class:`pipeline.transport.local.LocalTeam`) and one process per robot over
  Zenoh (:class:`pipeline.transport.zenoh_transport.ZenohTransport`).

Who uses it: the consistency stage (:mod:`pipeline.consistency`) sends every message through
endpoints; the fusion consensus (:mod:`pipeline.fusion.landmarks`) is a vectorized
evaluation of every robot's update: on a faulty network each of its logical rounds goes
through the robots' reliable channels in lockstep (:mod:`pipeline.fusion.protocol`), on a
fault-free one it counts its traffic in bulk (:meth:`Transport.count`).

Byte encoding (stated, so numbers are comparable): a message is a fixed 12-byte header
(sender, receiver, kind/length as three int32) followed by its payload arrays, each counted at
its numpy ``nbytes``.

May import: the shared words of the root (and, in :mod:`.zenoh_transport`, Zenoh).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

__all__ = ["HEADER_BYTES", "Message", "NotANeighbourError", "Transport", "Endpoint",
           "RoundEndpoint", "RobotMissingError", "NO_NEIGHBOUR_EXIT"]

HEADER_BYTES = 12


class NotANeighbourError(RuntimeError):
    """A robot tried to send to a robot that is not its current communication neighbour."""


class RobotMissingError(RuntimeError):
    """A neighbour never answered the start handshake of a team (the message names it)."""


#: exit code of a robot process (``python -m pipeline robot``) that heard no neighbour in its
#: start handshake (:class:`RobotMissingError`)
NO_NEIGHBOUR_EXIT = 3


@dataclass
class Message:
    """One packet between two neighbouring robots.

    Attributes
    ----------
    src, dst : int — sending and receiving robot
    kind : str — e.g. ``blocks`` (detection), ``request`` or ``reject`` (resolution)
    payload : dict[str, ndarray] — index or value arrays
    sent_round : int — round in which it was sent
    """

    src: int
    dst: int
    kind: str
    payload: dict
    sent_round: int = 0

    @property
    def nbytes(self) -> int:
        """Size on the wire: header plus the payload arrays."""
        return HEADER_BYTES + int(sum(np.asarray(a).nbytes for a in self.payload.values()))


class Transport(ABC):
    """Synchronous message passing between the ``n`` robots of a team.

    Per round: every robot reads its inbox and sends; then the driver calls
    :meth:`end_round`, and what was sent is in the inboxes of a later round (the next one on a
    lossless network).
    """

    n: int

    # --- the clock and the barrier (driver side) -----------------------------------------
    @property
    @abstractmethod
    def round(self) -> int:
        """The current round (counted from 0 over the transport's life)."""

    @abstractmethod
    def end_round(self) -> None:
        """Close the round: advance the clock and deliver what is due."""

    @property
    @abstractmethod
    def pending(self) -> bool:
        """True while some sent message has not been delivered yet."""

    @abstractmethod
    def alive(self, i: int) -> bool:
        """False once robot ``i`` has crashed (the driver's view; robots cannot call this)."""

    # --- what a robot does (through its :class:`Endpoint`) --------------------------------
    @abstractmethod
    def send(self, src: int, dst: int, kind: str, payload: dict) -> None:
        """Queue a message from ``src`` to its current neighbour ``dst`` (counted).

        Raises :class:`NotANeighbourError` if ``dst`` is not a current neighbour of ``src``.
        """

    @abstractmethod
    def inbox(self, i: int) -> list[Message]:
        """Messages delivered to robot ``i`` at the start of the current round."""

    @abstractmethod
    def links_up(self, i: int) -> frozenset:
        """Robot ``i``'s neighbour table this round (crashes unseen: inferred from silence)."""

    # --- the graph per round (vectorized stages) ------------------------------------------
    @abstractmethod
    def edges(self, t: int) -> np.ndarray:
        """Communication links up in round ``t``, ``(E_t, 2)`` int64 (every robot's table)."""

    @property
    @abstractmethod
    def switching(self) -> bool:
        """True when the links change from round to round."""

    @property
    @abstractmethod
    def window(self) -> int:
        """Rounds within which every link is up at least once (1 on a static network)."""

    @property
    @abstractmethod
    def faulty(self) -> bool:
        """True unless this is the paper's lossless static network."""

    def injected_faults(self) -> dict:
        """What a simulator injects, for the report: ``drop_probability``,
        ``switching_topology``, ``crash_rounds`` (robot -> round). A real network injects
        nothing (its losses are counted as they happen)."""
        return dict(drop_probability=0.0, switching_topology=self.switching, crash_rounds={})

    # --- accounting -----------------------------------------------------------------------
    @abstractmethod
    def count(self, kind: str, messages: int, nbytes: int) -> None:
        """Count traffic exchanged in bulk (a vectorized stage's rounds) under ``kind``."""

    @abstractmethod
    def counters(self) -> dict:
        """``messages``, ``bytes``, ``dropped``, ``round``, ``messages_by_kind``,
        ``bytes_by_kind`` so far."""

    @abstractmethod
    def note_memory(self, i: int, nbytes: int) -> None:
        """Robot ``i`` reports the bytes it holds; the transport keeps the peak."""

    @abstractmethod
    def peak_memory(self, i: int) -> int:
        """Peak of the bytes robot ``i`` reported."""

    def endpoint(self, i: int) -> Endpoint:
        """Robot ``i``'s view of the transport."""
        return Endpoint(self, i)


class Endpoint:
    """One robot's side of a :class:`Transport`: all a robot may do with the network.

    Parameters
    ----------
    transport : Transport
    robot_id : int
    """

    def __init__(self, transport: Transport, robot_id: int) -> None:
        self._transport = transport
        self.id = int(robot_id)

    def send(self, dst: int, kind: str, payload: dict) -> None:
        """Send to a current neighbour ``dst``."""
        self._transport.send(self.id, dst, kind, payload)

    def inbox(self) -> list[Message]:
        """Messages delivered to this robot at the start of the current round."""
        return self._transport.inbox(self.id)

    def links_up(self) -> frozenset:
        """This robot's neighbour table in the current round."""
        return self._transport.links_up(self.id)

    @property
    def now(self) -> int:
        """The current round."""
        return self._transport.round

    def note_memory(self, nbytes: int) -> None:
        """Report the bytes this robot holds (the transport keeps the peak)."""
        self._transport.note_memory(self.id, nbytes)


class RoundEndpoint(Endpoint):
    """One robot's side of a network of synchronous rounds with no driver behind it.

    A robot in its own program has no driver playing the clock: it closes each round itself
    with :meth:`end_round` — what it sent leaves, and what its neighbours sent in the same
    round comes back as the next round's inbox, with each neighbour's round state. Messages
    and bytes are counted as :class:`Transport` counts them; faults (loss, a neighbour that
    stops answering) are properties of the transport, never of the robot code. Robot-side
    code (the reliable protocol's :class:`~pipeline.consistency.channel.Channel`) uses it
    exactly as an :class:`Endpoint`.

    Attributes
    ----------
    robot_id : int
    neighbours : frozenset of int — communication neighbours in the comm graph
    round : int — current logical round (0 before the first :meth:`end_round`)
    """

    robot_id: int
    neighbours: frozenset
    round: int = 0
    _last_inbox: list = []
    _peak_memory: int = 0

    @property
    def id(self) -> int:  # the Endpoint attribute
        return int(self.robot_id)

    @abstractmethod
    def send(self, dst: int, kind: str, payload: dict) -> None:
        """Queue an algorithm message to neighbour ``dst`` for this round (counted)."""

    @abstractmethod
    def end_round(self, state: dict | None = None) -> tuple[list[Message], dict[int, dict]]:
        """Close the round; return the next round's inbox and the neighbours' round states.

        ``state`` (small JSON-able dict) travels to every neighbour with this round's packet;
        the returned dict maps each neighbour still heard to the state it sent this round.
        A neighbour that stopped answering (crash) is absent from it; the inbox then simply
        holds nothing from it, as when a message is lost.
        """

    def inbox(self) -> list[Message]:
        """The inbox returned by the last :meth:`end_round`."""
        return list(self._last_inbox)

    def links_up(self) -> frozenset:
        """The robot's neighbour table (a crash cannot be seen, only inferred from silence)."""
        return self.neighbours

    @property
    def now(self) -> int:
        return int(self.round)

    def note_memory(self, nbytes: int) -> None:
        self._peak_memory = max(self._peak_memory, int(nbytes))

    def peak_memory(self) -> int:
        """Peak of the bytes this robot reported."""
        return int(self._peak_memory)

    @abstractmethod
    def counters(self) -> dict:
        """``messages``, ``bytes`` (counted as the simulator does), ``dropped``,
        ``messages_by_kind``, ``bytes_by_kind``, and for a real middleware ``wire_bytes`` and
        ``wire_packets``."""

    def close(self) -> None:
        """Release the connection (default: nothing)."""
        return None
