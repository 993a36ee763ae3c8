"""The ``sync`` rule run by one robot alone (its own process), deciding by itself when a phase
ends.

In the simulator the driver of :func:`.sync.run_sync` ends each phase when nothing is in
flight and reads one bit per robot. A robot in its own process runs the same phase code
(:mod:`.sync`) over the reliable channel of :mod:`.reliable` (acknowledged messages,
retransmission, loss timeout) and ends each phase by the termination wave of
:mod:`.termination`: *done* is "every message I sent is acknowledged" (a message in flight
keeps its sender not done, so all robots done at one round means nothing is in flight), and
the wave's bit ``CONFLICT`` carries "some cluster still holds an eligible link" (phase A) to
every robot of the connected team, so all robots take the same branch.

Phases: support, then (exchange and best → if no robot holds an eligible link: stop; else
merge) repeated — as in :func:`.sync.run_sync`. The clusters do not depend on when a message
arrives within a phase (the best is a maximum, a merge needs the two ends' bests of the same
phase, a relabel applies once), so a robot alone ends with the simulator's clusters.

A lost neighbour (silent for ``loss_timeout`` rounds while expected, :mod:`.channel`): its
links are cut (``robot-lost``), the wave's ``LOST`` bit tells the whole team at the phase's
end, and every robot starts the rule again from its own features with the links it has left
(the clusters of the interrupted run may hold stale knowledge of the lost robot). Each loss
restarts at most once per lost robot, so at most ``n`` restarts.
"""

from __future__ import annotations

from pipeline.consistency.reliable import AlonePhases
from pipeline.consistency.robot import Robot
from pipeline.consistency.sync import (
    equip_sync,
    exchange_step,
    finish_sync,
    has_best,
    merge_step,
    start_exchange,
    start_merge,
    start_support,
    support_step,
)
from pipeline.consistency.wave import CONFLICT, LOST, RobotRun
from pipeline.errors import StageStalledError

__all__ = ["run_sync_locally"]


def run_sync_locally(robot: Robot, transport, protocol, n_robots: int | None = None) -> RobotRun:
    """The ``sync`` rule for one robot over its end of the network (module docstring).

    Parameters
    ----------
    robot : Robot — equipped by :func:`.sync.equip_sync`
    transport : RoundEndpoint — its end of the network (``end_round`` closes each round)
    protocol : ProtocolOptions — timers of the reliable channel
    n_robots : int or None — team size ``n`` (the wave's threshold; default ``robot.n``)

    Returns
    -------
    RobotRun — ``iterations`` the Borůvka rounds, ``resolution_rounds`` all network rounds,
    ``repeated_detections`` the restarts after a loss, ``phases`` one record per phase.

    Bounds: each phase ends ``n - 1`` rounds after the last robot became done; a phase that
    does not end within a cap derived from ``n``, ``m`` and the timeout raises
    ``RuntimeError`` naming the robot and the phase (a bug, never a correct run).
    """
    run = AlonePhases(robot, transport, protocol, n_robots)
    st, log, n = run.st, run.log, run.n
    weight, flood = robot.sync.weight.copy(), robot.sync.flood

    def run_phase(name: str, start, step) -> int:
        t, out, begin = run.phase(
            name, start, lambda rb, msgs, send, now, t: step(rb, msgs, send, now),
            lambda: (CONFLICT if name == "sync-exchange" and has_best(robot) else 0)
            | (LOST if st.lost_in_phase else 0),
            memory=lambda: robot.fixed_bytes() + robot.sync.nbytes() + run.chan.memory_bytes())
        log.phases.append(dict(phase=name, start_round=begin, rounds=t, bits=int(out)))
        log.resolution_rounds += t
        return out

    restarts = 0
    while True:
        bits = run_phase("sync-support", start_support, support_step)
        boruvka = 0
        while not bits & LOST:
            bits = run_phase("sync-exchange", start_exchange, exchange_step)
            if bits & LOST or not bits & CONFLICT:
                break
            boruvka += 1
            if boruvka > robot.m_total:
                raise StageStalledError(f"robot {robot.id}: sync did not end within "
                                        f"{robot.m_total} Borůvka rounds")
            bits = run_phase("sync-merge", start_merge, merge_step)
        if not bits & LOST:
            break
        restarts += 1
        if restarts > n:
            raise RuntimeError(f"robot {robot.id}: more than {n} restarts after losses")
        # a neighbour was lost somewhere: start again from the links that are left, with the
        # same flood graph
        equip_sync(robot, weight, flood)
    finish_sync(robot, transport.round)
    log.iterations = boruvka
    log.repeated_detections = restarts
    return run.close()
