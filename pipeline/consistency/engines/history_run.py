"""The robots' history check (:mod:`pipeline.consistency.history`) on the simulator.

Every robot of a step's sub-problem steps on its own inbox, phase after phase, each phase
until nothing is in flight (the end a robot alone learns from the termination wave). Where a
robot alone skips a phase because the wave's bits say no robot needs it, here the phase
runs and ends at once: no robot has anything to send, so the decisions are the same.

Bounds (the caps only turn a bug into an error; a correct run never reaches them). Phase 1
floods over *features*, one link per round: the two smallest pieces of a set are final at
every feature within ``D`` rounds, ``D`` the set's diameter in links; a flag is raised by
then and floods another ``D``; the last messages arrive in round ``2 D + 1``. A set after
the rule's cuts may hold one frame many times (the rule cut history links, which stay), so
``D`` is bounded by the features, not the frames: ``D < m_sum``, cap ``2 m_sum + 2`` (three
frames chaining ``r_i - x_i = y_i - r_{i+1}`` through ``k`` pieces, ``=`` a history link the
paper rule cuts, give ``D = 3 k``). Phases 2 and 3 go over *robots* (a set's tree of frames,
depth at most ``n - 1``): the echo ends within ``2 n`` rounds (tokens out, echoes back), the
repair within ``3 n - 2`` (request down, halves up, cuts down): cap ``3 n + 6``.
"""

from __future__ import annotations

import numpy as np

from pipeline.commgraph import comm_edges_for
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.engines.phases import run_quiet_phase
from pipeline.consistency.history import PHASES, HistoryInputs, equip_history
from pipeline.transport.simulated import Network
from pipeline.types import Links

__all__ = ["run_history"]


def run_history(features_per_camera, links: Links, alive: np.ndarray,
                inputs: list[HistoryInputs]) -> dict:
    """The check on the stage's cameras: ``links`` the stage's links (real and history), each
    robot's rows alive where ``alive`` (the links the stage kept), ``inputs`` one per camera.

    Returns ``cut`` (sorted link ids the robots cut), ``rounds``, ``messages``, ``bytes``
    (``bytes_by_kind``), ``phases`` (rounds of each phase), ``peak_bytes`` (a robot's
    largest state at the end)."""
    fpc = np.asarray(features_per_camera, np.int64)
    robots, link_index = build_robots(fpc, links)
    alive = np.asarray(alive, bool)
    for rb, idx in zip(robots, link_index, strict=True):
        rb.link_alive = alive[idx].copy()
        equip_history(rb, inputs[rb.id])
    network = Network(len(fpc), comm_edges_for(fpc, links, None))
    phases = {}
    # module docstring: phase 1 floods over features, the others over the frames' trees
    caps = dict(names=2 * int(fpc.sum()) + 2)
    for name, start, step, finish in PHASES:
        phases[name] = run_quiet_phase(
            robots, network, start,
            lambda rb, inbox, send, t, step=step: step(rb, inbox, send, t),
            what=f"history {name}", cap=caps.get(name, 3 * len(robots) + 6))
        if finish is not None:
            for rb in robots:
                finish(rb)
    c = network.counters()
    cut = np.unique(np.concatenate([np.asarray(rb.history.cut, np.int64) for rb in robots])
                    if robots else np.zeros(0, np.int64))
    return dict(cut=cut, rounds=int(sum(phases.values())), messages=int(c["messages"]),
                bytes=int(c["bytes"]), phases=phases, bytes_by_kind=c["bytes_by_kind"],
                peak_bytes=int(max((rb.history.nbytes() for rb in robots), default=0)))
