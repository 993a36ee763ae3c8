"""One robot's fusion stage run alone, in its own process, over its own endpoint.

:func:`run_fusion_locally` steps a :class:`~pipeline.fusion.robot.FusionRobot` round after
round on a fault-free network and ends the stage by the termination wave of
:mod:`pipeline.consistency.termination`; :func:`run_fusion_reliably` does the same on a lossy
network, every logical round over the reliable channel in lockstep (a ``fusion-tick`` when a
robot has nothing to send), so the computation is the fault-free one.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import StageStalledError
from pipeline.fusion.robot import FusionRobot

__all__ = ["run_fusion_locally", "run_fusion_reliably", "TICK"]


def run_fusion_locally(fusion: FusionRobot, transport, n_robots: int | None = None,
                       max_rounds: int | None = None) -> dict:
    """Run robot ``fusion.i``'s fusion over ``transport`` (a
    :class:`~pipeline.transport.RoundEndpoint`) until the termination wave ends the phase.

    Returns
    -------
    dict — ``rounds`` (transport rounds of the phase), ``fusion_rounds`` (the largest max-c
    plus consensus round count of the team, flooded with the wave), ``local_rounds``, ``lost``
    (neighbours that fell silent during the phase)
    """
    from pipeline.consistency.termination import TerminationWave

    n = int(n_robots or fusion.n)
    wave = TerminationWave(n)
    cap = max_rounds or (n + fusion.opt.rounds + 2 * n + 8)
    silent_before = set(getattr(transport, "silent", ()))
    heard_max = 0
    wave.start(fusion.done, 0)
    t = 0
    while True:
        for dst, kind, payload in fusion.messages():
            transport.send(dst, kind, payload)
        inbox, states = transport.end_round({**wave.state(), "r": int(heard_max),
                                             "phase": "fusion"})
        t += 1
        silent = set(getattr(transport, "silent", ())) - silent_before
        # a neighbour whose packet did not come this round is gone for the phase
        gone = {k for k in fusion.alive if k not in states} | silent
        fusion.receive(inbox, sorted(gone))
        if fusion.done:
            heard_max = max(heard_max, fusion.local_rounds)
        for s in states.values():
            heard_max = max(heard_max, int(s.get("r", 0)))
        if wave.update(fusion.done, 0, states):
            return dict(rounds=t, fusion_rounds=int(heard_max),
                        local_rounds=int(fusion.local_rounds), lost=sorted(fusion.lost))
        if t > cap:
            raise StageStalledError(f"robot {fusion.i}: fusion did not end within {cap} rounds")


TICK = "fusion-tick"


def run_fusion_reliably(fusion: FusionRobot, transport, options=None,
                        n_robots: int | None = None, max_rounds: int | None = None) -> dict:
    """Like :func:`run_fusion_locally` on a lossy network: every logical round over the
    reliable channel of the consistency stage, in lockstep.

    Each logical round the robot sends every neighbour still heard exactly one message through
    its :class:`~pipeline.consistency.channel.Channel` (sequence numbers, acknowledgements,
    retransmission; an empty ``fusion-tick`` when the round has nothing for it), tagged with
    the round and whether it is the robot's last; it then turns network rounds until it holds
    the message of that round from every neighbour that has not sent its last (or has been
    declared lost: silent for ``loss_timeout`` rounds while expected, or its process gone).
    So the logical computation is the fault-free one (an α-synchronizer, as
    :class:`pipeline.fusion.protocol.LockstepExchange` in the simulator); only network rounds
    and retransmissions grow. The phase ends by the termination wave once the robot is done
    and everything it sent is acknowledged.
    """
    from pipeline.consistency.channel import Channel
    from pipeline.consistency.protocols import ProtocolOptions
    from pipeline.consistency.termination import TerminationWave

    n = int(n_robots or fusion.n)
    chan = Channel(transport, options or ProtocolOptions(reliable=True))
    wave = TerminationWave(n)
    cap = max_rounds or 200 * (n + fusion.opt.rounds + 8)
    silent_before = set(getattr(transport, "silent", ()))
    held: dict[int, dict[int, object]] = {}   # logical round -> sender -> message
    fin_at: dict[int, int] = {}               # neighbour -> its last logical round
    heard_max = 0
    lost_now: set[int] = set()
    state = {"t": 0, "rounds": 0}
    wave.start(False, 0)

    def turn() -> bool:
        """One network round; True when the wave ends the phase."""
        nonlocal heard_max
        inbox, states = transport.end_round({**wave.state(), "r": int(heard_max),
                                             "phase": "fusion"})
        state["rounds"] += 1
        now = transport.round
        for m in chan.receive(inbox, now):
            t = int(m.payload["t"][0])
            held.setdefault(t, {})[m.src] = m
            if int(m.payload["fin"][0]):
                fin_at[m.src] = t
        chan.flush(now)
        waiting = {j for j in fusion.alive - chan.lost - lost_now
                   if fin_at.get(j, 1 << 30) >= state["t"]
                   and j not in held.get(state["t"], {})} if not fusion.done else set()
        gone = set(chan.check_lost(now, waiting_on=waiting))
        gone |= (set(getattr(transport, "silent", ())) - silent_before) & fusion.alive
        for k in gone:
            chan.lost.add(k)
        lost_now.update(gone)
        if fusion.done:
            heard_max = max(heard_max, fusion.local_rounds)
            late = [m for t in sorted(held) for m in held.pop(t).values()]
            fusion.receive([m for m in late if m.kind != TICK], sorted(lost_now))
            lost_now.clear()
        for s in states.values():
            heard_max = max(heard_max, int(s.get("r", 0)))
        if state["rounds"] > cap:
            raise StageStalledError(f"robot {fusion.i}: fusion did not end within {cap} rounds")
        return wave.update(fusion.done and chan.idle(), 0, states)

    while not fusion.done:
        t = state["t"]
        out = {dst: (kind, payload) for dst, kind, payload in fusion.messages()}
        fin = fusion.phase == "cut"
        for j in sorted(fusion.alive - chan.lost):
            kind, payload = out.get(j, (TICK, {}))
            chan.send(j, kind, {**payload, "t": np.array([t], np.int32),
                                "fin": np.array([int(fin)], np.uint8)}, transport.round)
        while True:
            expect = {j for j in fusion.alive - chan.lost - lost_now
                      if fin_at.get(j, 1 << 30) >= t}
            if expect <= set(held.get(t, {})):
                break
            if turn():
                break
        got = held.pop(t, {})
        fusion.receive([m for m in got.values() if m.kind != TICK], sorted(lost_now))
        lost_now.clear()
        state["t"] = t + 1
    while not turn():
        pass
    return dict(rounds=state["rounds"], fusion_rounds=int(heard_max),
                local_rounds=int(fusion.local_rounds), lost=sorted(fusion.lost),
                logical_rounds=state["t"], retransmissions=chan.retransmissions,
                acks=chan.acks_sent)
