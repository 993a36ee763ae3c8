"""The loop of Prop. 4.5 run by one robot alone over the reliable channel, each phase ended by
the termination wave (the rule and its proof: :mod:`.termination`).

Kept apart from :mod:`.termination` (which picks a rule's functions from :mod:`.rules`) so
that a rule's own robot-alone entry (``paper-labels``: :func:`run_paper_labels_locally`) can
run it without the registry importing itself.
"""

from __future__ import annotations

import time

from pipeline.consistency.channel import Channel
from pipeline.consistency.evidence import CASE_EVIDENCE, evidence_step, start_evidence
from pipeline.consistency.labels import labels_done, labels_round, start_labels_reliable
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.reliable import (
    AlonePhases,
    ReliableState,
    close_log,
    closing_round,
    detection_done,
    detection_round,
    resolution_done,
    resolution_round,
    start_closing,
    start_detection_reliable,
    start_resolution_reliable,
)
from pipeline.consistency.resolution import finish_resolution
from pipeline.consistency.robot import Robot
from pipeline.consistency.roots import roots_step, start_roots
from pipeline.consistency.setlists import (
    bundle_budget,
    finish_setlists,
    setlists_step,
    start_setlists,
)
from pipeline.consistency.sync import CASE_SYNC, equip_sync
from pipeline.consistency.sync_alone import run_sync_locally
from pipeline.consistency.wave import CONFLICT, LOST, RobotRun, TerminationWave, run_wave_phase

__all__ = ["DETECTIONS", "ALG1", "LARGE", "run_loop_locally", "run_paper_labels_locally",
           "run_evidence_locally", "run_history_locally", "LostInPhase"]

#: the detections a robot alone can run: ``(start, round, done)`` over the reliable channel
DETECTIONS = {
    "rows": (start_detection_reliable, detection_round, detection_done),
    "labels": (start_labels_reliable, labels_round, labels_done),
}
#: Alg. 1 over the reliable channel: ``(start, step, done, finish)``
ALG1 = (start_resolution_reliable, resolution_round, resolution_done, finish_resolution)


def _own_bits(robot: Robot, st: ReliableState) -> int:
    return (CONFLICT if robot.conflictive.any() else 0) | (LOST if st.lost_in_phase else 0)


def _run_phase(robot: Robot, st: ReliableState, transport, wave: TerminationWave, step, done,
               max_rounds: int, phase: str) -> tuple[int, int]:
    """Rounds of one phase until the wave ends it; returns (rounds, OR of the bits)."""
    return run_wave_phase(transport, wave, step, done, lambda: _own_bits(robot, st), max_rounds,
                          phase, robot.id, lambda: robot.peak_memory_bytes)


def run_loop_locally(robot: Robot, transport, protocol: ProtocolOptions | None, n_robots,
                     hooks, detection: str = "rows") -> RobotRun:
    """Detection and a resolution rule until conflict-free (:func:`.termination.
    run_consistency_locally` has the parameters); ``hooks`` the rule's robot-alone
    ``(start, step, done, finish)``, ``detection`` a key of :data:`DETECTIONS`."""
    protocol = protocol or ProtocolOptions(reliable=True)
    rule_start, rule_step, rule_done, rule_finish = hooks
    det_start, det_round, det_done = DETECTIONS[detection]
    n = int(n_robots or robot.n)
    # the reliable protocol's own state, exactly as the simulator's ReliableProtocol holds it
    st = ReliableState(Channel(transport, protocol))
    chan = st.chan
    wave = TerminationWave(n)
    m_total = robot.m_total
    # generous caps, as in the simulator's driver: they only turn a bug into an error
    det_cap = (m_total + n + 4) * (protocol.loss_timeout + 4) * 4 + n
    res_cap = (n + 2) * (protocol.loss_timeout + 4) * 4 + m_total + n
    max_iterations = m_total // 4 + 2 + n * n
    log = RobotRun()
    t_start = time.perf_counter()
    iteration = 0
    passes = 0
    redo = False  # a detection repeated after a loss stays in its iteration
    while True:
        passes += 1
        if not redo:
            iteration += 1
        redo = False
        if passes > max_iterations:
            raise RuntimeError(f"robot {robot.id}: conflicts remain after {max_iterations} "
                               "iterations (Prop. 4.5 bound)")
        start = transport.round
        det_start(robot, st, iteration, transport.round)
        rounds, bits = _run_phase(
            robot, st, transport, wave,
            lambda inbox, now, t: det_round(robot, st, inbox, now, t),
            lambda: det_done(robot, st), det_cap, "detection")
        log.detection_rounds += rounds
        log.phases.append(dict(phase="detection", iteration=iteration, start_round=start,
                               rounds=rounds, t_stop=int(robot.t_stop),
                               conflictive_features=int(robot.conflictive.sum()),
                               conflict_somewhere=bool(bits & CONFLICT),
                               lost_somewhere=bool(bits & LOST)))
        if bits & LOST:
            log.repeated_detections += 1
            redo = True
            continue
        if not bits & CONFLICT:
            # every linked neighbour confirms it is alive (reliable.py, "Closing round")
            start = transport.round
            start_closing(robot, st, transport.round)
            rounds, bits = _run_phase(
                robot, st, transport, wave,
                lambda inbox, now, t: closing_round(robot, st, inbox, now, t),
                chan.idle, res_cap, "closing")
            log.closing_rounds += rounds
            log.phases.append(dict(phase="closing", iteration=iteration, start_round=start,
                                   rounds=rounds, lost_somewhere=bool(bits & LOST)))
            if bits & LOST:
                log.repeated_detections += 1
                redo = True
                continue
            break
        log.iterations += 1
        start = transport.round
        roots = rule_start(robot, st, transport.round)
        rounds, bits = _run_phase(
            robot, st, transport, wave,
            lambda inbox, now, t: rule_step(robot, st, inbox, now, t),
            lambda: rule_done(robot, st, bool(wave.bits & LOST)), res_cap, "resolution")
        # what the next detection examines again (Alg. 1: the unassigned conflictive
        # features, Sec. IV after Cor. 4.4; the evidence rule: its sets, now conflict-free)
        rule_finish(robot)
        log.resolution_rounds += rounds
        log.phases.append(dict(phase="resolution", iteration=iteration, start_round=start,
                               rounds=rounds, roots=int(roots), lost_somewhere=bool(bits & LOST)))
    return close_log(log, st, t_start)


def run_paper_labels_locally(robot: Robot, transport, protocol: ProtocolOptions | None = None,
                             n_robots: int | None = None) -> RobotRun:
    """The ``paper-labels`` rule for a robot alone: the loop with the label flooding of
    :mod:`.labels` as its detection and Alg. 1 as its resolution."""
    return run_loop_locally(robot, transport, protocol, n_robots, ALG1, detection="labels")



#: the third bit of the evidence rule's wave (beside ``CONFLICT`` and ``LOST``): some robot
#: holds a feature of a set of more than ``B`` features
LARGE = 4


class LostInPhase(RuntimeError):
    """A robot was lost in a phase whose work a loss leaves undone (the sets solved at their
    roots, the history check): ``run`` is the robot's run log up to there (its
    ``lost_neighbours`` name the lost). A robot whose team is started again on a loss
    (option ``restarted_on_loss``, :mod:`pipeline.team.robot`) publishes it; else the
    robot fails with it."""

    def __init__(self, message: str, run) -> None:
        super().__init__(message)
        self.run = run


def run_evidence_locally(robot: Robot, transport, protocol: ProtocolOptions | None = None,
                         n_robots: int | None = None) -> RobotRun:
    """The ``evidence`` rule for a robot alone: the phases of the simulator's stage
    (:mod:`.engines.evidence_stage`) over the reliable channel, each ended by the wave.

    1. Bounded label flooding (:mod:`.setlists`, ``B`` from the robot's
       :class:`~.evidence.EvidenceState` or the team's default); the wave ORs ``CONFLICT``
       (a small conflictive set), ``LARGE`` and ``LOST``. A robot's flags are read every
       round and the OR keeps a flag raised before more ids arrived (a set first seen small
       and conflictive, then large): it only makes the next phase run, where nothing waits.
    2. With ``CONFLICT``: the evidence rule's flood and solve (:func:`.evidence.start_evidence`,
       :func:`.evidence.evidence_step`) on the small conflictive sets; the wave ends it when
       nothing is in flight, when every set is solved unless a robot was lost. Skipped when
       the robot's :class:`~.evidence.EvidenceState` says ``solve_small = False`` (every
       robot alike: the caller solves those sets, e.g. the online stage at their roots).
    2b. With ``gather_free``, or ``gather_conflictive`` and ``CONFLICT`` (every robot
       alike): the small sets solved at their roots (:mod:`.roots`), the wave ending it when
       nothing is in flight. A loss there is an error (a set may be left unsolved).
    3. With ``LARGE``: the robot hides its links outside large sets and runs the ``sync``
       merge alone (:func:`.sync_alone.run_sync_locally`, its own channel and wave, both
       started at the same round by every robot), then shows them again.

    A loss (``LOST``) in phase 1 or 2 starts again from phase 1 on the links left (the sets
    solved keep their cuts and are found conflict-free), as the detection loop repeats a
    detection after a loss.
    """
    protocol = protocol or ProtocolOptions(reliable=True)
    run = AlonePhases(robot, transport, protocol, n_robots)
    st, log, chan = run.st, run.log, run.chan
    B = bundle_budget(robot.n, robot.evidence.bundle_budget)

    def lists_bits() -> int:
        return ((CONFLICT if robot.conflictive.any() else 0)
                | (LARGE if robot.setlists.large.any() else 0)
                | (LOST if st.lost_in_phase else 0))

    def lists_start(rb, send) -> None:
        start_setlists(rb, 1, send, B)
        finish_setlists(rb)

    def lists_step(rb, msgs, send, now, t) -> None:
        setlists_step(rb, msgs, send, t)
        finish_setlists(rb)

    restarts = 0
    while True:
        t, bits, begin = run.phase(
            "setlists", lists_start, lists_step, lists_bits,
            memory=lambda: robot.memory_bytes() + robot.setlists.nbytes() + chan.memory_bytes())
        log.detection_rounds += t
        log.phases.append(dict(phase="setlists", start_round=begin, rounds=t, bits=int(bits)))
        if not bits & LOST and bits & CONFLICT and robot.evidence.floods_small():
            t, ebits, begin = run.phase(
                "evidence", lambda rb, send: start_evidence(rb, send),
                lambda rb, msgs, send, now, t: evidence_step(rb, msgs, send, t),
                lambda: LOST if st.lost_in_phase else 0,
                memory=lambda: (robot.memory_bytes() + robot.evidence.nbytes()
                                + chan.memory_bytes()))
            log.resolution_rounds += t
            log.phases.append(dict(phase="evidence", start_round=begin, rounds=t,
                                   bits=int(ebits)))
            bits |= ebits & LOST
        if not bits & LOST:
            break
        restarts += 1
        if restarts > run.n:
            raise RuntimeError(f"robot {robot.id}: more than {run.n} restarts after losses")
    log.repeated_detections = restarts
    ev = robot.evidence
    if ev.gather_free or (ev.gather_conflictive and bits & CONFLICT):
        if hasattr(transport, "status"):  # to the observer (a launcher's fault injection)
            transport.status("roots")
        t, rbits, begin = run.phase(
            "roots", lambda rb, send: start_roots(rb, send),
            lambda rb, msgs, send, now, t: roots_step(rb, msgs, send, t),
            lambda: LOST if st.lost_in_phase else 0,
            memory=lambda: robot.memory_bytes() + robot.roots.nbytes() + chan.memory_bytes())
        log.resolution_rounds += t
        log.phases.append(dict(phase="roots", start_round=begin, rounds=t, bits=int(rbits)))
        if rbits & LOST:  # a set that lost a robot may stay unsolved: said, never hidden
            raise LostInPhase(f"robot {robot.id}: a robot was lost while the sets were "
                              "solved at their roots", run.close())
    merge = None
    if bits & LARGE:
        alive = robot.link_alive.copy()
        hidden = alive & ~robot.setlists.large[robot.link_r]
        robot.link_alive = alive & ~hidden
        equip_sync(robot, robot.evidence.link_weight)
        merge = run_sync_locally(robot, transport, protocol, n_robots)
        robot.deleted_case[alive & ~robot.link_alive & (robot.deleted_case == CASE_SYNC)] = \
            CASE_EVIDENCE
        robot.link_alive = robot.link_alive | hidden
    log.iterations = int((robot.deleted_case == CASE_EVIDENCE).any())
    out = run.close()
    if merge is not None:
        out.resolution_rounds += merge.resolution_rounds
        out.phases.extend(merge.phases)
        out.repeated_detections += merge.repeated_detections
        for k in ("retransmissions", "acks", "heartbeats"):
            setattr(out, k, getattr(out, k) + getattr(merge, k))
        out.lost_neighbours = sorted(set(out.lost_neighbours) | set(merge.lost_neighbours))
    return out


def run_history_locally(robot: Robot, transport, protocol: ProtocolOptions | None = None,
                        n_robots: int | None = None) -> RobotRun:
    """The history check of an online step (:mod:`.history`) for a robot alone, after its
    rule: the robot must hold its inputs (:func:`.history.equip_history`). Its phases over
    the reliable channel, each ended by the termination wave, whose bits say every robot
    alike whether the next is needed: the echo only where some set has two pieces or more
    (``MANY``) or is flagged (``BAD``), the repair only where some set is bad. A robot lost in the
    check is an error (a bad set could stay unrepaired): said, never hidden. The links it
    cuts are in ``robot.history.cut``."""
    from pipeline.consistency.history import BAD, MANY, PHASES

    protocol = protocol or ProtocolOptions(reliable=True)
    run = AlonePhases(robot, transport, protocol, n_robots)
    st, log = run.st, run.log

    def lost() -> int:
        return LOST if st.lost_in_phase else 0

    def memory() -> int:
        return robot.memory_bytes() + robot.history.nbytes() + run.chan.memory_bytes()

    def phase(name: str, start, step, finish) -> int:
        bits = (lambda: finish(robot)) if finish is not None else (lambda: 0)
        t, out, begin = run.phase(f"history-{name}", lambda rb, send: start(rb, send),
                                  lambda rb, msgs, send, now, t: step(rb, msgs, send, t),
                                  lambda: bits() | lost(), memory=memory)
        log.resolution_rounds += t
        log.phases.append(dict(phase=f"history-{name}", start_round=begin, rounds=t,
                               bits=int(out)))
        if out & LOST:
            raise LostInPhase(f"robot {robot.id}: a robot was lost in the history check",
                              run.close())
        bits()  # the state after the phase (the wave may have asked before its last round)
        return out

    # the wave ORs every robot's bits (they only grow within a phase)
    names, echo, repair = PHASES
    if phase(*names) & (MANY | BAD) and phase(*echo) & BAD:
        phase(*repair)
    return run.close()
