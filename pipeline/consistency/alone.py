"""The loop of Prop. 4.5 run by one robot alone over the reliable channel, each phase ended by
the termination wave (the rule and its proof: :mod:`.termination`).

Kept apart from :mod:`.termination` (which picks a rule's functions from :mod:`.rules`) so
that a rule's own robot-alone entry (``paper-labels``: :func:`run_paper_labels_locally`) can
run it without the registry importing itself.
"""

from __future__ import annotations

import time

from pipeline.consistency.channel import Channel
from pipeline.consistency.evidence import (
    evidence_done,
    evidence_round,
    reexamine_sets,
    start_evidence_reliable,
)
from pipeline.consistency.labels import labels_done, labels_round, start_labels_reliable
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.reliable import (
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
from pipeline.consistency.wave import CONFLICT, LOST, RobotRun, TerminationWave, run_wave_phase

__all__ = ["DETECTIONS", "ALG1", "EVIDENCE", "run_loop_locally", "run_paper_labels_locally",
           "run_evidence_locally"]

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
    while True:
        iteration += 1
        if iteration > max_iterations:
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


#: the evidence rule over the reliable channel (:mod:`.evidence`): ``(start, step, done, finish)``
EVIDENCE = (start_evidence_reliable, evidence_round, evidence_done, reexamine_sets)


def run_evidence_locally(robot: Robot, transport, protocol: ProtocolOptions | None = None,
                         n_robots: int | None = None) -> RobotRun:
    """The ``evidence`` rule for a robot alone: the loop with the rows of Sec. III as its
    detection and the evidence rule's flood and solve as its resolution.

    On every set of at most ``B`` features (the bundle budget of :mod:`.setlists`) its cuts
    are those of the simulator's stage (:mod:`.engines.evidence_stage`: the same bundles and
    solution); a larger set is solved here by its bundles too (memory ``Σ |C|²``), where the
    simulator's stage runs the ``sync`` merge on its links."""
    return run_loop_locally(robot, transport, protocol, n_robots, EVIDENCE, detection="rows")
