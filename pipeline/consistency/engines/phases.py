"""The one phase loop of the simulator: every robot of a team steps on its inbox, round after round.

Used by the per-robot engine (:mod:`.driver`) for every phase and by the batched resolution
(:mod:`.batched_resolution`) where it falls back to stepping the robots one by one.
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.protocols import DETECTION, RESOLUTION, end_phase
from pipeline.consistency.robot import Robot
from pipeline.errors import StageStalledError
from pipeline.transport import Transport

__all__ = ["run_phase", "run_resolution_phase", "run_quiet_phase"]


def run_phase(robots: list[Robot], network: Transport, protocol, phase: str, iteration: int = 0,
              max_rounds: int | None = None, on_round=None) -> dict:
    """One phase (``detection`` or ``resolution``) on all robots: the one loop of the stage.

    Round 0: every robot of the protocol's team starts the phase. Then, round after round,
    the network delivers and every robot of the team (those still alive, for the reliable
    protocol) takes one step on its inbox, until the protocol says the phase is over.

    ``on_round`` (callable ``(round) -> None`` or None) is told each round (progress).

    Returns
    -------
    dict — ``rounds``, ``start_round`` (network round of round 0), ``lost`` (some robot
    declared a neighbour lost); detection: ``t_stop`` (n,) the round each robot stopped
    (Prop. 3.5), ``conflictive_features``; resolution: ``conflictive_sets`` (sets rooted,
    eq. 10); closing: nothing more
    """
    start_round = int(network.round)
    live = protocol.team(robots)
    rooted = sum(protocol.start(phase, rb, iteration) for rb in live)
    cap = protocol.max_rounds(phase, robots) if max_rounds is None else max_rounds
    t = 0
    while True:
        live = protocol.team(live)
        if protocol.done(phase, live):
            break
        network.end_round()
        t += 1
        if on_round is not None:
            on_round(t)
        for rb in protocol.team(live):
            protocol.step(phase, rb, network.inbox(rb.id), t)
        if t > cap:
            raise StageStalledError(f"{phase} did not end within {cap} rounds")
    end_phase(phase, robots)
    out = dict(rounds=t, start_round=start_round, lost=protocol.lost_in_phase(live))
    if phase == DETECTION:
        out.update(t_stop=np.array([rb.t_stop for rb in robots], dtype=np.int64),
                   conflictive_features=int(sum(int(rb.conflictive.sum()) for rb in live)))
    elif phase == RESOLUTION:
        out.update(conflictive_sets=int(rooted))
    return out


def run_resolution_phase(robots: list[Robot], network: Transport, protocol, iteration: int,
                         on_round=None) -> dict:
    """Alg. 1 (the ``paper`` rule's pass, :mod:`pipeline.consistency.rules`): the resolution
    phase of :func:`run_phase` with the protocol's robot steps."""
    return run_phase(robots, network, protocol, RESOLUTION, iteration, on_round=on_round)


def run_quiet_phase(robots: list[Robot], network: Transport, start, step, on_round=None,
                    t0: int = 0, cap: int | None = None, what: str = "phase") -> int:
    """A phase of a rule that floods (``sync``, label flooding) on every robot until nothing
    is in flight — the phase end a robot alone learns from the termination wave; returns the
    rounds taken.

    Round 0 ``start(robot, send)`` on every robot; then, round after round, every robot with
    mail takes ``step(robot, inbox, send, t0 + t)``. ``cap``: rounds after which it raises
    ``RuntimeError`` (a bug, never a correct run; default ``2 n + 4``)."""
    cap = 2 * len(robots) + 4 if cap is None else cap
    sends = [lambda dst, kind, p, i=rb.id: network.send(i, dst, kind, p) for rb in robots]
    for rb in robots:
        start(rb, sends[rb.id])
    t = 0
    while network.pending:
        network.end_round()
        t += 1
        if on_round is not None:
            on_round(t0 + t)
        receivers = network.receivers() if hasattr(network, "receivers") else range(len(robots))
        for i in receivers:
            step(robots[i], network.inbox(i), sends[i], t0 + t)
        if t > cap:
            raise StageStalledError(f"{what} did not end within {cap} rounds")
    return t
