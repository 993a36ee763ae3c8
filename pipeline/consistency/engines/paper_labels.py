"""The ``paper-labels`` rule in the simulator: label-flooding detection
(:mod:`pipeline.consistency.labels`) and Alg. 1, every robot stepping on its own inbox.

The driver plays only the clock and the phase barrier (nothing in flight), as the
termination wave of a robot alone would (:func:`.labels.run_paper_labels_locally`).
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.engines.phases import run_quiet_phase, run_resolution_phase
from pipeline.consistency.labels import finish_labels, labels_step, start_labels
from pipeline.consistency.protocols import PaperProtocol
from pipeline.consistency.robot import Robot
from pipeline.transport import Transport

__all__ = ["run_labels", "run_paper_labels"]


def run_labels(robots: list[Robot], network: Transport, iteration: int, on_round=None,
               t0: int = 0) -> dict:
    """One label-flooding detection of every robot (each on its own inbox), ended when
    nothing is in flight; returns what :func:`.engines.phases.run_phase` returns for a
    detection."""
    start_round = int(network.round)
    # labels settle within diam(C) rounds, the dup flags and root keys they reveal flood
    # another diam(C): 2 diam + 1 rounds, and diam < m_sum (pipeline.consistency.labels)
    cap = 2 * int(sum(rb.m for rb in robots)) + 2
    # the robots count the phase's own rounds (t_stop); the progress report, the stage's
    tell = None if on_round is None else (lambda t: on_round(t0 + t))
    t = run_quiet_phase(robots, network, lambda rb, send: start_labels(rb, iteration, send),
                        labels_step, tell, 0, cap, "label flooding")
    for rb in robots:
        finish_labels(rb)
        network.note_memory(rb.id, rb.peak_memory_bytes)  # also when no resolution follows
    return dict(rounds=t, start_round=start_round, lost=False,
                t_stop=np.array([rb.t_stop for rb in robots], dtype=np.int64),
                conflictive_features=int(sum(int(rb.conflictive.sum()) for rb in robots)))


def run_paper_labels(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """The ``paper-labels`` rule in the simulator: label-flooding detection, then Alg. 1
    (:func:`.engines.phases.run_resolution_phase`), until a detection finds no conflictive
    feature (Prop. 4.5). Returns ``rounds``, ``iterations``, ``detection_rounds``,
    ``resolution_rounds`` and ``conflictive_sets`` (sets rooted over all passes)."""
    proto = PaperProtocol(network, len(robots), True)
    m_total = robots[0].m_total if robots else 0
    det = res = sets = 0
    iteration = 0
    while True:
        iteration += 1
        if iteration > m_total // 4 + 2:
            raise RuntimeError(f"conflicts remain after {iteration - 1} iterations "
                               "(Prop. 4.5 bound)")
        d = run_labels(robots, network, iteration, on_round, det + res)
        det += d["rounds"]
        if d["conflictive_features"] == 0:
            break
        r = run_resolution_phase(robots, network, proto, iteration)
        res += r["rounds"]
        sets += r["conflictive_sets"]
    return dict(rounds=det + res, iterations=iteration, detection_rounds=det,
                resolution_rounds=res, conflictive_sets=sets)
