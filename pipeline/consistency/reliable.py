"""Fault-tolerant robot protocol for the consistency stage: lossy links, crashes, switching links.

The paper's algorithms (Aragüés et al., Sec. III and Alg. 1) assume a lossless synchronous
network. Their only rule for a missing message is "use the last matrix received, because the
neighbour has finished" (Sec. III, after Cor. 3.6), which is true on a lossless network and
false on a lossy one: a dropped block makes a robot see "no change" and stop early (Prop. 3.5
fires on stale data), and a dropped component request or reject leaves a conflict or a
half-deleted link. Measured (``bench/faults.py``, 200 formations of 4–10 robots): with the
paper's rule alone the first detection was exact in 13 % / 0 % / 0 % of the runs at loss
``p`` = 0.1 / 0.3 / 0.5 (it stopped after 6.3 / 5.2 / 3.9 network rounds on average instead of
6.6) and the loop ended conflict-free in 72.5 % / 43.5 % / 38 %. With this protocol: exact and
conflict-free in 100 % at every ``p``, the first detection taking 17.7 / 27.2 / 43.9 rounds.

This module adds what is needed, *in the robots* (every extra packet is an algorithm message,
sent and counted by the network, which itself only drops, delays or cuts):

Reliable channel (:class:`~.channel.Channel`, one per robot, in :class:`ReliableState`)
    Every algorithm message to a neighbour gets a sequence number; the receiver acknowledges
    it (piggybacked on its next message to that neighbour, else in a small ``ack`` message
    in the same round) and delivers it once (duplicates are discarded by sequence number).
    An unacknowledged message is sent again every round once ``retransmit_after`` rounds
    have passed since its first sending (on a lossless network the acknowledgement arrives
    exactly then, so nothing is ever sent twice). While a link is down (switching topology)
    messages wait and go out when it is up again.

Lockstep detection (:func:`detection_round`; eq. (5) itself is :func:`~.detection.eq5_step`)
    Eq. (5) is computed on the blocks of the *same* round: robot ``i`` forms ``X_i·(t+1)``
    only when it holds ``X_k·(t)`` from every neighbour ``k`` it shares an active link with
    (an α-synchronizer over the reliable channel). Then ``X_i·(t)`` is exactly the lossless
    one (row ``r`` = features within ``t`` hops of ``f_r^i``), Prop. 3.5 stops exactly at the
    same ``t_i`` and Cor. 3.6 (``t_i ≤ d + 1`` logical rounds) holds; only the number of
    network rounds grows with the loss. A robot that stops sends ``final(t_i)`` to every
    neighbour it has a link with: "my blocks of round ``t_i − 1`` are my blocks for every later
    round" — the paper's "use the last matrix received" made explicit, since a receiver can no
    longer tell a finished neighbour from a lost message. A robot's detection is *done* when it
    has stopped, received every linked neighbour's ``final`` and had all its messages acked.

Reliable resolution
    Alg. 1 (:mod:`.resolution`) runs unchanged on the messages the channel delivers. Alg. 1
    is insensitive to delivery delays: case (c) is decided by the receiving robot alone, every
    feature that joins a component sends requests along all its other links (so every link
    between two assigned features is examined by one end), and a duplicate request is case
    (a) or a stale link (rejected again), so nothing is done twice. A resolution ends when no
    robot has an unacknowledged message.

Crashes and timeouts (stated)
    A robot *expects* a neighbour ``k`` when it waits for an acknowledgement from ``k``, or
    for ``k``'s blocks or ``final`` during a detection. A robot that has not stopped its
    detection sends a ``heartbeat`` to a linked neighbour it sent nothing to for
    ``heartbeat_every`` rounds. A neighbour that stays silent for ``loss_timeout`` rounds
    (``T``, default 40) while expected is declared lost: every link to it is cut (reason
    ``robot-lost``), pending messages to it are dropped, and it is ignored from then on (so a
    neighbour wrongly suspected also times out on this robot and cuts its side). So no robot
    waits more than ``T`` rounds for anyone. ``T`` trades detection speed against wrong
    suspicions: with loss probability ``p`` a live neighbour heard at least every round is
    missed for ``T`` rounds with probability about ``p^T``; one heard only through acks of
    retransmissions, about ``(1 - (1 - p)^2)^(T - 2)`` (``p = 0.5``, ``T = 40``: 2e-5).
    With a switching topology ``T`` must exceed the longest outage of a link.
    A phase ends when every robot *alive* is done, so messages a robot sent just before it
    crashed may still be in flight (with a delay) and arrive in a later phase: the channel
    acknowledges them (to a dead robot: nobody hears it) and the phase code ignores a kind
    that is not its own. A receiver that still holds a link to the crashed robot declares it
    lost in the next detection, where it waits for that robot's blocks and ``final`` in vain
    (``T`` rounds; late messages from it arrive within ``1 + delay`` rounds, after which
    the channel ignores the lost robot). A message to a robot that crashed while it was in flight is lost,
    like a dropped one.

What detection needs on a topology that changes every round (stated and tested)
    * Every comm edge that carries associations must *recur* (be up at least once in every
      window of ``W`` rounds): the blocks ``X_k·`` that ``W_ik`` multiplies can only travel
      over the edge ``(i, k)``, so the joint connectivity of Assumption 2.1 of the fusion
      paper is not enough (:func:`~pipeline.transport.simulated.recurrent_topology` makes such sequences).
    * A robot must not take step ``t + 1`` of eq. (5), and so must not apply Prop. 3.5,
      while the round-``t`` blocks of a neighbour it was unable to reach are missing: with
      the paper's rule a neighbour out of range looks "unchanged" and the robot stops early.
      Lockstep gives this for free.
    * A robot must not end its detection while a linked neighbour has not confirmed its own
      end (``final``), nor before that neighbour has its ``final``.
    * ``T > W`` plus a few rounds of retransmission, or an outage is taken for a crash (the
      link is then cut as ``robot-lost`` on both sides, which keeps the survivors consistent
      but loses the link).

Closing round (stated): no crash before the end goes unnoticed
    A detection that lost nobody and found no conflictive feature would end the loop, but a
    robot may crash after it sent everything that detection needed from it (its blocks, its
    ``final``, its acknowledgements): nobody expects anything from it any more, so nobody
    notices, and its links stay kept although it is dead. So the loop does not end on that
    detection but on a *closing phase* after it (:func:`start_closing`, :func:`closing_round`):
    every robot alive sends an acknowledged ``closing`` message to every neighbour it still
    shares an alive link with, and its closing is done when all of them are acknowledged
    (``Channel.idle``). A neighbour that does not acknowledge within ``T`` rounds is declared
    lost like any silent neighbour: its links are cut (``robot-lost``), and the phase's
    ``lost`` bit makes the driver run the detection again (whose result then no longer
    includes the lost robot), followed by a new closing phase.

    Rule: a robot that crashed before it acknowledged the closing message of every neighbour
    it shares a link with — in particular any robot dead when the last closing phase starts,
    or before the closing messages reach it (``1 + delay`` rounds later) — has every link
    to a survivor cut as ``robot-lost``. A robot that crashes after acknowledging all of them
    has completed the stage (the driver reports it under ``crashed_after_close``); its links
    stay kept, as every robot alive at the close holds them.

    Why the end state is conflict-free among the survivors. The last detection lost nobody,
    so its lockstep rows are exact (Prop. 3.5) for the links alive among the robots that took
    part in it, and it found no conflictive feature: those links form no conflictive set
    (Def. 2.4). The closing phase after it cuts nothing (else it would not be the last), so
    the final links are exactly those; every survivor, and every robot that crashed after the
    close, took part in it. The survivors' links are a subset, hence conflict-free too.
    Links held *only* by robots that crashed before the close (between two crashed robots)
    are no survivor's; nobody can cut them, and the driver reports them as they were left.

What a detection in which some robot lost a neighbour found is not trusted (blocks that
came through the lost robot may reach beyond what the survivors can reach): the driver skips
the resolution and runs the detection again (:mod:`.engine`); the loop of Prop. 4.5 ends on a
detection that lost nobody and found no conflict. In a deployment that one bit travels with
the phase barrier, like the "conflicts found" bit the driver already gathers.

Wire format (counted by the network): every channel message carries ``seq`` (int32, 0 for
unsequenced ``ack``/``heartbeat``) and, when it acknowledges something, ``ack`` (int32 list of
the sender's sequence numbers being acknowledged); ``blocks`` carry ``t`` (int32, logical
round) besides the paper's ``rows``/``indptr``/``indices``; ``final`` carries ``t`` = ``t_i``;
``closing`` carries only its ``seq``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from pipeline.consistency.channel import Channel
from pipeline.consistency.detection import (
    blocks_from_payload,
    eq5_step,
    find_conflictive_sets,
    init_detection,
    send_blocks,
)
from pipeline.consistency.resolution import resolution_step, start_resolution
from pipeline.consistency.robot import ROBOT_LOST, Robot, blocks_bytes
from pipeline.consistency.wave import RobotRun, TerminationWave, run_wave_phase
from pipeline.transport import Message

__all__ = ["ReliableState", "start_detection_reliable", "detection_round",
           "detection_done", "start_resolution_reliable", "resolution_round", "start_closing",
           "closing_round", "cut_lost", "measure_state", "resolution_done"]

_I32 = np.int32


@dataclass
class ReliableState:
    """What one robot keeps for the fault-tolerant protocol (besides its :class:`Robot` state).

    Attributes
    ----------
    chan : Channel — its reliable links
    t_logical : int — logical round ``t`` of the lockstep detection
    recv_blocks : dict ``k -> {t: (rows, block)}`` — neighbours' blocks ``X_k·(t)`` by round
    final_t : dict ``k -> t_k`` — neighbours' ``final`` markers (their stop round)
    block_nbrs : set — neighbours whose blocks the next step of eq. (5) waits for
    all_nbrs : set — neighbours it shares an alive link with (they get its ``final``)
    lost_neighbours : set — neighbours it declared lost (over the whole run)
    lost_in_phase : bool — it declared a neighbour lost during the current phase
    """

    chan: Channel
    t_logical: int = 0
    recv_blocks: dict = field(default_factory=dict)
    final_t: dict = field(default_factory=dict)
    block_nbrs: set = field(default_factory=set)
    all_nbrs: set = field(default_factory=set)
    lost_neighbours: set = field(default_factory=set)
    lost_in_phase: bool = False

    def memory_bytes(self) -> int:
        """Bytes of the blocks held by round plus the channel's buffers."""
        held = sum(blocks_bytes(per_round.values()) for per_round in self.recv_blocks.values())
        return held + self.chan.memory_bytes()


class AlonePhases:
    """A robot alone running a rule's flooding phases over the reliable channel, each ended by
    the termination wave (:mod:`.wave`): what the rules without the paper's detection loop
    (:mod:`.sync_alone`, :mod:`.labels`) share.

    A phase: round 0 ``start(robot, send)``; then, per network round, the messages the channel
    delivers go to ``step(robot, msgs, send, now, t)`` (``t`` the phase round), a neighbour
    silent past the loss timeout is cut (``robot-lost``, :func:`cut_lost`), and the wave ends
    the phase when every robot is *done* (everything it sent acknowledged: nothing in flight)
    with the OR of every robot's ``bits()``. ``cap``: rounds after which a phase that did not
    end raises ``RuntimeError`` (a bug, never a correct run): ``(m + n + 4)`` rounds of loss
    timeout plus four, four times over.

    Attributes: ``n``, ``st`` (:class:`ReliableState`), ``chan``, ``wave``, ``cap``, ``log``
    (:class:`~.wave.RobotRun`).
    """

    def __init__(self, robot: Robot, transport, protocol, n_robots: int | None = None):
        self.robot, self.transport = robot, transport
        self.n = int(n_robots or robot.n)
        self.st = ReliableState(Channel(transport, protocol))
        self.chan = self.st.chan
        self.wave = TerminationWave(self.n)
        self.cap = (robot.m_total + self.n + 4) * (protocol.loss_timeout + 4) * 4
        self.log = RobotRun()
        self._t0 = time.perf_counter()

    def phase(self, name: str, start, step, bits, memory=None) -> tuple[int, int, int]:
        """Run one phase; returns ``(rounds, OR of the bits over the team, start round)``.
        ``memory()``: bytes to count in the robot's peak after each round (optional)."""
        robot, chan, st, transport = self.robot, self.chan, self.st, self.transport
        now = transport.round
        nbrs = set(np.unique(robot.link_nbr[robot.link_alive]).tolist())
        start(robot, lambda dst, kind, p: chan.send(dst, kind, p, now))
        chan.flush(now, heartbeat_to=sorted(nbrs - chan.lost))
        st.lost_in_phase = False
        begin = transport.round

        def round_(inbox, now, t):
            msgs = chan.receive(inbox, now)
            lost = chan.check_lost(now, nbrs - chan.lost)
            if lost:
                cut_lost(robot, st, lost, now)
            step(robot, msgs, lambda dst, kind, p: chan.send(dst, kind, p, now), now, t)
            chan.flush(now, heartbeat_to=sorted(nbrs - chan.lost))
            if memory is not None:
                robot.peak_memory_bytes = max(robot.peak_memory_bytes, memory())

        t, out = run_wave_phase(transport, self.wave, round_, chan.idle, bits, self.cap, name,
                                robot.id, lambda: robot.peak_memory_bytes)
        return t, out, begin

    def close(self):
        """The run log with its time and the channel's counts; returns it."""
        return close_log(self.log, self.st, self._t0)


def close_log(log, st: ReliableState, t0: float):
    """Fill a robot's run log at its end: seconds since ``t0`` (``time.perf_counter``), the
    channel's retransmissions, acknowledgements and heartbeats, the neighbours it lost."""
    log.seconds = time.perf_counter() - t0
    log.retransmissions = st.chan.retransmissions
    log.acks = st.chan.acks_sent
    log.heartbeats = st.chan.heartbeats_sent
    log.lost_neighbours = sorted(int(k) for k in st.lost_neighbours)
    return log


# ------------------------------------------------------------------------------------------
# helpers on the robot

def cut_lost(robot: Robot, st: ReliableState, lost: list[int], round_: int) -> None:
    """Cut every alive link to a neighbour declared lost (reason ``robot-lost``)."""
    if not lost:
        return
    links = np.flatnonzero(robot.link_alive & np.isin(robot.link_nbr, lost))
    robot.delete_links(links, round_, ROBOT_LOST)
    st.lost_neighbours.update(int(k) for k in lost)
    st.lost_in_phase = True


def measure_state(robot: Robot, st: ReliableState) -> None:
    """Peak memory of the robot including the protocol's blocks and retransmission buffers."""
    robot.peak_memory_bytes = max(robot.peak_memory_bytes, robot.memory_bytes() + st.memory_bytes())


def _linked_neighbours(robot: Robot, rows_mask: np.ndarray | None = None) -> set[int]:
    sel = robot.link_alive if rows_mask is None else robot.link_alive & rows_mask[robot.link_r]
    return set(np.unique(robot.link_nbr[sel]).tolist())


# ------------------------------------------------------------------------------------------
# detection (Sec. III) in lockstep over the reliable channel

def _send_blocks_reliable(robot: Robot, st: ReliableState, now: int) -> None:
    """The paper's blocks message (eq. 5 rows), tagged with the logical round ``t``."""
    t = np.array([st.t_logical], dtype=_I32)
    send_blocks(robot, lambda dst, kind, p: st.chan.send(dst, kind, {"t": t, **p}, now))


def _send_finals(robot: Robot, st: ReliableState, now: int) -> None:
    """After Prop. 3.5 fired at ``t_i``: ``final(t_i)`` to every linked neighbour."""
    t = np.array([robot.t_stop], dtype=_I32)
    for k in sorted(st.all_nbrs - st.chan.lost):
        st.chan.send(k, "final", {"t": t}, now)


def start_detection_reliable(robot: Robot, st: ReliableState, iteration: int, now: int) -> None:
    """Round 0: eq. (4) as in :func:`~.detection.start_detection`, blocks sent reliably."""
    st.lost_in_phase = False
    st.recv_blocks = {}
    st.final_t = {}
    st.t_logical = 0
    rows = init_detection(robot, iteration)
    st.block_nbrs = _linked_neighbours(robot, robot.active) - st.chan.lost
    st.all_nbrs = _linked_neighbours(robot) - st.chan.lost
    robot.stopped = False
    if rows.size == 0:
        robot.stopped = True  # Prop. 3.5 at t_i = 0: no active row
        robot.t_stop = 0
        find_conflictive_sets(robot)
        _send_finals(robot, st, now)
    else:
        _send_blocks_reliable(robot, st, now)
    robot.measure_memory()


def _blocks_of_round(robot: Robot, st: ReliableState, k: int, t: int):
    """``X_k·(t)`` as received, or ``None`` if it has not arrived yet."""
    got = st.recv_blocks.get(k, {})
    if t in got:
        return got[t]
    tk = st.final_t.get(k)
    if tk is not None and t >= tk - 1:
        # k stopped at t_k: X_k(t) = X_k(t_k - 1) for every t >= t_k - 1 (Prop. 3.5)
        if tk <= 0:
            return np.zeros(0, _I32), sp.csr_matrix((0, robot.m_total), dtype=bool)
        return got.get(tk - 1)
    return None


def detection_round(robot: Robot, st: ReliableState, inbox: list[Message], now: int,
                    phase_round: int) -> None:
    """One network round of the lockstep detection for one robot.

    Receives blocks and finals, declares silent neighbours lost (cutting their links), and
    computes one step of eq. (5) (:func:`~.detection.eq5_step`) when the blocks of the current
    logical round ``t`` from every neighbour of an active link are in; stops by Prop. 3.5.
    """
    chan = st.chan
    for m in chan.receive(inbox, now):
        p = m.payload
        if m.kind == "blocks":
            st.recv_blocks.setdefault(m.src, {})[int(p["t"][0])] = blocks_from_payload(robot, p)
        elif m.kind == "final":
            st.final_t[m.src] = int(p["t"][0])
    waiting = {k for k in st.all_nbrs if k not in st.final_t}
    if not robot.stopped:
        waiting |= {k for k in st.block_nbrs
                    if _blocks_of_round(robot, st, k, st.t_logical) is None}
    lost = chan.check_lost(now, waiting)
    if lost:
        cut_lost(robot, st, lost, phase_round)
        st.block_nbrs -= set(lost)
        st.all_nbrs -= set(lost)
    if not robot.stopped:
        t = st.t_logical
        blocks = {k: _blocks_of_round(robot, st, k, t) for k in st.block_nbrs}
        if all(b is not None for b in blocks.values()):
            if eq5_step(robot, blocks, t + 1):
                _send_finals(robot, st, now)
            else:
                st.t_logical = t + 1
                _send_blocks_reliable(robot, st, now)
            # later rounds need X_k(t + 1), or X_k(t) if k stops at t + 1, or the last
            # blocks of a k that has stopped: drop the others
            for k, got in st.recv_blocks.items():
                keep = st.final_t.get(k, 0) - 1
                for tt in [tt for tt in got if tt < t and tt != keep]:
                    del got[tt]
    chan.flush(now, heartbeat_to=() if robot.stopped else sorted(st.all_nbrs))
    measure_state(robot, st)


def detection_done(robot: Robot, st: ReliableState) -> bool:
    """Stopped, every linked neighbour's ``final`` received, every message acknowledged."""
    return robot.stopped and all(k in st.final_t for k in st.all_nbrs) and st.chan.idle()


# ------------------------------------------------------------------------------------------
# resolution (Alg. 1) over the reliable channel

def start_resolution_reliable(robot: Robot, st: ReliableState, now: int) -> int:
    """Alg. 1 lines 2–5 with the requests sent reliably; returns the sets this robot roots."""
    st.lost_in_phase = False
    return start_resolution(robot, lambda dst, kind, p: st.chan.send(dst, kind, p, now))


def resolution_round(robot: Robot, st: ReliableState, inbox: list[Message], now: int,
                     phase_round: int) -> None:
    """One network round of Alg. 1 (lines 8–19) on the messages the channel delivers."""
    msgs = st.chan.receive(inbox, now)
    lost = st.chan.check_lost(now)
    if lost:
        cut_lost(robot, st, lost, phase_round)
    msgs = [m for m in msgs if m.kind in ("request", "reject")]
    resolution_step(robot, msgs, lambda dst, kind, p: st.chan.send(dst, kind, p, now), phase_round)
    st.chan.flush(now)
    measure_state(robot, st)


# ------------------------------------------------------------------------------------------
# closing phase: every linked neighbour confirms it is alive (module docstring)

def resolution_done(robot: Robot, st: ReliableState, lost_somewhere: bool) -> bool:
    """The *done* predicate of Alg. 1 for a robot alone (:mod:`.termination`): every message
    it sent is acknowledged."""
    return st.chan.idle()


def start_closing(robot: Robot, st: ReliableState, now: int) -> None:
    """Round 0 of the closing phase: an acknowledged ``closing`` to every linked neighbour.

    Done when all of them are acknowledged (``st.chan.idle()``); a neighbour silent for ``T``
    rounds is declared lost in :func:`closing_round`.
    """
    st.lost_in_phase = False
    for k in sorted(_linked_neighbours(robot) - st.chan.lost):
        st.chan.send(k, "closing", {}, now)
    measure_state(robot, st)


def closing_round(robot: Robot, st: ReliableState, inbox: list[Message], now: int,
                  phase_round: int) -> None:
    """One network round of the closing phase: acknowledge, retransmit, time out the silent.

    The channel acknowledges every ``closing`` received (and discards late duplicates of
    earlier phases); a neighbour that leaves a ``closing`` unacknowledged for ``T`` rounds is
    declared lost and its links cut (``robot-lost``).
    """
    st.chan.receive(inbox, now)
    lost = st.chan.check_lost(now)
    if lost:
        cut_lost(robot, st, lost, phase_round)
    st.chan.flush(now)
    measure_state(robot, st)
