"""The two robot protocols of the consistency stage, behind one interface for the phase loop.

A *protocol* says what a robot does when a phase (``detection``, Sec. III, or ``resolution``,
Alg. 1) starts, what it does in each network round, and when the phase is over:

* :class:`PaperProtocol` — the paper's algorithms as they are (:mod:`.detection`,
  :mod:`.resolution`), for the lossless static network they are proven on. A detection is
  over when every robot has stopped (Prop. 3.5) and nothing is in flight, a resolution when
  nothing is in flight. The paper's model has no crashes: every robot is stepped (the
  network discards what a crashed one sends or would receive).
* :class:`ReliableProtocol` — the fault-tolerant protocol of :mod:`.reliable` (acknowledged
  messages, lockstep detection, timeouts). A crashed robot is no longer stepped; a phase is
  over when every robot still alive is done. It has a third phase, ``closing``
  (:attr:`ReliableProtocol.closing`): after the last detection every robot has each linked
  neighbour confirm that it is alive, so that a crash after a robot's last detection is
  noticed (:mod:`.reliable`, "Closing round").

Each protocol holds every robot's endpoint on the transport (and, for the reliable one, the
per-robot :class:`~.reliable.ReliableState`); the driver (:func:`.engines.phases.run_phase`) only plays
the clock and the phase barrier.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.consistency.channel import Channel
from pipeline.consistency.detection import detection_step, start_detection
from pipeline.consistency.reliable import (
    ReliableState,
    closing_round,
    detection_done,
    detection_round,
    resolution_round,
    start_closing,
    start_detection_reliable,
    start_resolution_reliable,
)
from pipeline.consistency.resolution import finish_resolution, resolution_step, start_resolution
from pipeline.consistency.robot import Robot
from pipeline.errors import InputError
from pipeline.transport import Transport

__all__ = ["ProtocolOptions", "PaperProtocol", "ReliableProtocol", "make_protocol", "end_phase",
           "DETECTION", "RESOLUTION", "CLOSING"]

DETECTION, RESOLUTION, CLOSING = "detection", "resolution", "closing"


@dataclass
class ProtocolOptions:
    """Parameters of the robot protocol.

    Attributes
    ----------
    reliable : bool or None
        ``True``: the fault-tolerant protocol of this module; ``False``: the paper's protocol
        as is (lossless static network assumed); ``None``: fault-tolerant exactly when some
        fault switch of the network is on.
    retransmit_after : int
        Rounds after the first sending before an unacknowledged message is sent again (then
        every round). 2 = the round trip of a lossless network.
    heartbeat_every : int
        A robot still detecting sends a heartbeat to a linked neighbour it has sent nothing to
        for this many rounds.
    loss_timeout : int
        ``T``: rounds of silence from an expected neighbour after which it is declared lost.
    delta_messages : bool or None
        The paper's protocol only. ``True``: detection messages carry only the entries new
        since the last message (:mod:`.detection`, module notes); ``False``: whole blocks;
        ``None``: deltas exactly on the lossless static network they rely on (every message
        arrives in the next round). The fault-tolerant protocol always sends whole blocks.
    """

    reliable: bool | None = None
    retransmit_after: int = 2
    heartbeat_every: int = 2
    loss_timeout: int = 40
    delta_messages: bool | None = None

    def __post_init__(self) -> None:
        for name in ("reliable", "delta_messages"):  # 'no' was read as True
            v = getattr(self, name)
            if v is not None and not isinstance(v, (bool, np.bool_)):
                raise InputError(f"ProtocolOptions {name} {v!r}: give True, False or None")
        # loss_timeout 0 declared every neighbour lost at once: every link cut
        for name in ("retransmit_after", "heartbeat_every", "loss_timeout"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise InputError(f"ProtocolOptions {name} {v!r}: give a whole number of rounds "
                                 ">= 1")

    @classmethod
    def for_delay(cls, delay_rounds: int) -> ProtocolOptions:
        """The defaults with the timers set for a link latency of ``delay_rounds`` extra
        rounds: a lossless round trip takes ``2 (D + 1)`` rounds, so a message is resent after
        ``retransmit_after (D + 1)`` rounds and a neighbour is lost after ``loss_timeout + 4 D``
        silent rounds.

        Why ``4 D``: a message sent at round 0 whose copy or acknowledgement is dropped is
        resent at ``2 (D + 1)`` and every round after, and a copy sent at ``s`` is answered at
        ``s + 2 (D + 1)``; ``T`` silent rounds then hold ``T - 4 (D + 1) + 2`` tries, the
        ``T - 2`` of a lossless-latency link (module notes of :mod:`.reliable`) when
        ``T = loss_timeout + 4 D``. With ``+ 2 D`` they fell to ``loss_timeout - 2 - 2 D``,
        none from ``D = 19``: one dropped message made a live neighbour look crashed, and
        ``--drop-prob 0.1 --delay-rounds 40`` cut every link of formation d as
        ``robot-lost``. A delay alone never makes a live neighbour look crashed."""
        d = int(delay_rounds)
        base = cls()
        return cls(retransmit_after=base.retransmit_after * (d + 1),
                   loss_timeout=base.loss_timeout + 4 * d)


class PaperProtocol:
    """The paper's protocol (Secs. III–IV as written) on the transport ``network``."""

    name = "paper"
    #: the paper's loop ends on the detection that finds no conflict (no closing phase)
    closing = False

    def __init__(self, network: Transport, n: int, delta: bool = False):
        self.network = network
        self.delta = bool(delta)
        self.endpoints = [network.endpoint(i) for i in range(n)]

    def team(self, robots: list[Robot]) -> list[Robot]:
        """The robots stepped this round: all of them (the paper's model has no crashes)."""
        return robots

    def max_rounds(self, phase: str, robots: list[Robot]) -> int:
        """A cap that only turns a bug into an error: ``m + 2`` (detection), ``n + 2``."""
        if phase == DETECTION:
            return robots[0].m_total + 2 if robots else 0
        return len(robots) + 2

    def start(self, phase: str, robot: Robot, iteration: int) -> int:
        """Round 0 of a phase; returns the conflictive sets the robot roots (resolution)."""
        ep = self.endpoints[robot.id]
        rooted = 0
        if phase == DETECTION:
            start_detection(robot, iteration, ep.send)
        else:
            rooted = start_resolution(robot, ep.send)
        ep.note_memory(robot.peak_memory_bytes)
        return rooted

    def step(self, phase: str, robot: Robot, inbox: list, phase_round: int) -> None:
        """Round ``phase_round >= 1`` of the phase for one robot."""
        ep = self.endpoints[robot.id]
        if phase == DETECTION:
            detection_step(robot, inbox, ep.send, phase_round, self.delta)
        else:
            resolution_step(robot, inbox, ep.send, phase_round)
        ep.note_memory(robot.peak_memory_bytes)

    def done(self, phase: str, live: list[Robot]) -> bool:
        """Detection: every robot stopped and nothing in flight; resolution: nothing in flight."""
        if phase == DETECTION and not all(rb.stopped for rb in live):
            return False
        return not self.network.pending

    def lost_in_phase(self, live: list[Robot]) -> bool:
        return False

    def lost_neighbours(self, i: int) -> set:
        return set()

    def counters(self) -> dict:
        return dict(retransmissions=0, acks=0, heartbeats=0)


class ReliableProtocol:
    """The fault-tolerant protocol of :mod:`.reliable` on the transport ``network``."""

    name = "reliable"
    #: the loop ends with a closing phase after the last detection (:mod:`.reliable`)
    closing = True

    def __init__(self, network: Transport, n: int, options: ProtocolOptions, m_total: int):
        self.network = network
        self.options = options
        self.endpoints = [network.endpoint(i) for i in range(n)]
        self.state = [ReliableState(Channel(ep, options)) for ep in self.endpoints]
        # generous caps: they only turn a bug into an error, never end a correct run
        T = options.loss_timeout
        self._caps = {DETECTION: (m_total + n + 4) * (T + 4) * 4,
                      RESOLUTION: (n + 2) * (T + 4) * 4 + m_total,
                      CLOSING: (n + 2) * (T + 4) * 4}

    def team(self, robots: list[Robot]) -> list[Robot]:
        """The robots still alive (a crashed robot is dead: it is no longer stepped)."""
        return [rb for rb in robots if self.network.alive(rb.id)]

    def max_rounds(self, phase: str, robots: list[Robot]) -> int:
        return self._caps[phase]

    def start(self, phase: str, robot: Robot, iteration: int) -> int:
        st, ep = self.state[robot.id], self.endpoints[robot.id]
        rooted = 0
        if phase == DETECTION:
            start_detection_reliable(robot, st, iteration, ep.now)
        elif phase == CLOSING:
            start_closing(robot, st, ep.now)
        else:
            rooted = start_resolution_reliable(robot, st, ep.now)
        ep.note_memory(robot.peak_memory_bytes)
        return rooted

    def step(self, phase: str, robot: Robot, inbox: list, phase_round: int) -> None:
        step = {DETECTION: detection_round, RESOLUTION: resolution_round,
                CLOSING: closing_round}[phase]
        ep = self.endpoints[robot.id]
        step(robot, self.state[robot.id], inbox, ep.now, phase_round)
        ep.note_memory(robot.peak_memory_bytes)

    def done(self, phase: str, live: list[Robot]) -> bool:
        """Every robot alive done: detection (:func:`~.reliable.detection_done`), or idle
        (resolution, closing)."""
        if phase == DETECTION:
            return all(detection_done(rb, self.state[rb.id]) for rb in live)
        return all(self.state[rb.id].chan.idle() for rb in live)

    def lost_in_phase(self, live: list[Robot]) -> bool:
        """Some robot declared a neighbour lost during the phase."""
        return any(self.state[rb.id].lost_in_phase for rb in live)

    def lost_neighbours(self, i: int) -> set:
        return self.state[i].lost_neighbours

    def counters(self) -> dict:
        chans = [s.chan for s in self.state]
        return dict(retransmissions=int(sum(c.retransmissions for c in chans)),
                    acks=int(sum(c.acks_sent for c in chans)),
                    heartbeats=int(sum(c.heartbeats_sent for c in chans)))


def make_protocol(options: ProtocolOptions | None, network: Transport, features_per_camera):
    """The protocol the robots run: reliable iff asked, or (by default) iff a fault is on."""
    options = options or ProtocolOptions()
    fpc = np.asarray(features_per_camera)
    reliable = network.faulty if options.reliable is None else bool(options.reliable)
    if reliable:
        if options.delta_messages:
            raise InputError("delta messages need the paper's protocol on a lossless network; "
                             "the fault-tolerant protocol sends whole blocks: leave "
                             "delta_messages unset or False")
        return ReliableProtocol(network, len(fpc), options, int(fpc.sum()))
    delta = (not network.faulty) if options.delta_messages is None else bool(options.delta_messages)
    return PaperProtocol(network, len(fpc), delta)


def end_phase(phase: str, robots: list[Robot]) -> None:
    """Phase barrier: after a resolution every robot prepares its next detection."""
    if phase == RESOLUTION:
        for rb in robots:
            finish_resolution(rb)
