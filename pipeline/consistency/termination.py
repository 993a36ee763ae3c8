"""The consistency stage run by one robot alone, deciding by itself when each phase ends.

In the simulator a driver (:mod:`.engine`) sees every robot and ends a phase when all are
done. A robot in its own process has no such driver: it runs this loop over its end of the
network (:class:`pipeline.transport.RoundEndpoint`) with the same phase code —
detection and Alg. 1 of :mod:`.reliable` — and decides locally when a phase is over.

Phases (as in :func:`.engine.resolve_conflicts`, fault-tolerant protocol)
    detection (Sec. III, lockstep) → if some robot lost a neighbour during it: detection
    again; else if no robot found a conflictive feature: the closing phase (every linked
    neighbour acknowledges a ``closing`` message, :mod:`.reliable`) and stop, or detection
    again if it lost a neighbour; else resolution (Alg. 1, or the evidence rule of
    :mod:`.evidence`) and the next detection (Prop. 4.5).

Local termination rule (the termination wave)
    Each robot ``i`` has a *done* predicate that it evaluates on its own state after every
    round: detection — stopped by Prop. 3.5, every linked neighbour's ``final`` received and
    all its messages acknowledged (:func:`.reliable.detection_done`); resolution and closing —
    all its messages acknowledged (``Channel.idle``); evidence rule — all its messages
    acknowledged and every set it takes part in solved, or a loss known
    (:func:`.evidence.evidence_done`; its bit is sticky, so the predicate stays stable). With
    every round's packet it tells its neighbours a counter ``c_i``::

        c_i(t) = 0                                                   if not done_i(t)
        c_i(t) = 1 + min(c_i(t-1), min_{k ∈ N_i} c_k(t-1))           otherwise

    and ends the phase at the first round with ``c_i(t) >= n`` (``n`` = team size, public).

    Why it is correct. Unrolling the recursion, ``c_i(t) >= h`` holds exactly when every robot
    ``j`` was done throughout the rounds ``[t-h+1, t-dist(i, j)]`` (``dist`` in the comm graph
    of robots still heard). With ``h = n >= diameter + 1`` these windows share the round
    ``t - n + 1``: all robots were done *at the same round*. That is a stable state: a robot
    done with nothing unacknowledged has no message in flight (an unacknowledged message keeps
    its sender not done), so nobody can be woken again, and every later round is done too.
    Conversely once all robots are done from round ``t0`` on, every ``c_i`` reaches ``n``
    first at ``t0 + n - 1``, and not before (the last robot to become done was not done at
    ``t0 - 1``, which is inside every window of an earlier round). So every robot of a
    connected team ends the phase at the *same* round ``t0 + n - 1`` and starts the next one
    together, as the simulator's driver would, ``n - 1`` rounds later than the driver.

    The phase's two outcome bits (``conflict``: some robot found a conflictive feature;
    ``lost``: some robot declared a neighbour lost) are OR-flooded the same way
    (``b_i(t) = own_i(t) | b_i(t-1) | OR_k b_k(t-1)``). A robot's bits are final once it is
    done, so at ``t0 + n - 1`` every robot holds the OR over all robots within ``n - 1`` hops
    — the whole connected team.

    A crashed robot: its neighbours' transport stops hearing it; the protocol declares it lost
    after ``T`` silent rounds and cuts its links (``robot-lost``), which sets ``lost``; the
    survivors repeat the detection (as the simulator does) and end without it. If the crash
    splits the team, each part ends on its own, which is all it can do.
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.alone import run_loop_locally
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.robot import Robot
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule
from pipeline.consistency.wave import CONFLICT, LOST, RobotRun, TerminationWave

__all__ = ["TerminationWave", "RobotRun", "run_consistency_locally", "robot_link_log",
           "CONFLICT", "LOST"]


def run_consistency_locally(robot: Robot, transport, protocol: ProtocolOptions | None = None,
                            n_robots: int | None = None,
                            resolution: str = DEFAULT_RESOLUTION,
                            detection: str = "rows") -> RobotRun:
    """Detection and resolution until conflict-free, ended by the local rule (module docstring).

    Parameters
    ----------
    robot : Robot — this robot's associations (its blocks ``W_ij``)
    transport : RoundEndpoint — its end of the network
    protocol : ProtocolOptions or None — the fault-tolerant protocol's parameters
    n_robots : int or None — team size ``n`` (default ``robot.n``)
    resolution : str
        A rule of :mod:`.rules`, run by its robot-alone functions (``start``, ``step``,
        ``done``, ``finish``) and ended by the same wave: ``paper``, Alg. 1 over the reliable
        channel; ``evidence``, the flood-and-solve rule of :mod:`.evidence` (the robot must
        hold its evidence, :func:`.evidence.equip`), whose one pass leaves the sets it solved
        conflict-free for the next detection, as in the simulator.
    detection : str
        ``rows``: the paper's detection (Sec. III, eq. 5) in lockstep; ``labels``: the
        label flooding of :mod:`.labels` (the same outcome, memory that follows the links),
        ended by the wave like every other phase.

    Returns
    -------
    RobotRun
    """
    rule = get_rule(resolution)
    if not rule.detection:
        # a rule that is the whole stage (no detection) ends its own phases by the same wave
        return rule.hook("alone")(robot, transport, protocol or ProtocolOptions(reliable=True),
                                  n_robots)
    return run_loop_locally(robot, transport, protocol, n_robots,
                            tuple(rule.hook(h) for h in ("start", "step", "done", "finish")),
                            detection)


def robot_link_log(robot: Robot) -> dict:
    """The robot's link table and deletion log as arrays (what it publishes at the end)."""
    return {"link_nbr": robot.link_nbr.astype(np.int32), "link_r": robot.link_r.astype(np.int32),
            "link_s": robot.link_s.astype(np.int32),
            "link_alive": robot.link_alive.astype(np.uint8),
            "deleted_case": robot.deleted_case.astype(np.int8),
            "deleted_round": robot.deleted_round.astype(np.int32),
            "deleted_iteration": robot.deleted_iteration.astype(np.int32),
            "component": robot.component.astype(np.int64)}
