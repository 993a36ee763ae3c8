"""The termination wave of a robot alone: one counter and the OR-flooded bits of a phase.

The rule and why it is correct are in :mod:`.termination` ("Local termination rule"); this
module holds the counter itself and a robot's run log, so that every robot-alone phase loop
(the detection loop of :mod:`.termination`, rules that are the whole stage such as
:mod:`.sync_alone`) ends its phases the same way.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pipeline.errors import StageStalledError

__all__ = ["TerminationWave", "RobotRun", "run_wave_phase", "CONFLICT", "LOST"]

CONFLICT, LOST = 1, 2


class TerminationWave:
    """The counter ``c_i`` and the OR-flooded bits of one phase (module docstring).

    Parameters
    ----------
    n : int — team size (the threshold of the rule)
    """

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self.c = 0
        self.bits = 0

    def start(self, done: bool, own_bits: int) -> None:
        """Round of the phase start: no history yet."""
        self.c = 1 if done else 0
        self.bits = int(own_bits)

    def update(self, done: bool, own_bits: int, neighbour_states: dict) -> bool:
        """Fold in the neighbours' states of the previous round; True when the phase ends."""
        cs = [int(s.get("c", 0)) for s in neighbour_states.values()]
        bits = self.bits | int(own_bits)
        for s in neighbour_states.values():
            bits |= int(s.get("b", 0))
        self.c = (1 + min([self.c, *cs])) if done else 0
        self.bits = bits
        return self.c >= self.n

    def state(self) -> dict:
        """What travels to the neighbours with this round's packet."""
        return {"c": self.c, "b": self.bits}


@dataclass
class RobotRun:
    """What one robot did in the consistency stage (its own log, for reporting)."""

    iterations: int = 0
    repeated_detections: int = 0
    phases: list = field(default_factory=list)
    detection_rounds: int = 0
    resolution_rounds: int = 0
    closing_rounds: int = 0
    seconds: float = 0.0


def run_wave_phase(transport, wave: TerminationWave, step, done, bits, max_rounds: int,
                   phase: str, robot_id: int, memory) -> tuple[int, int]:
    """Rounds of one phase of a robot alone until the wave ends it (:mod:`.termination`).

    ``step(inbox, now, t)`` is the robot's round on its inbox, ``done()`` its *done* predicate,
    ``bits()`` its own outcome bits, ``memory()`` its current peak bytes (reported to the
    transport each round). Returns ``(rounds, OR of the bits over the team)``; a phase not
    ended within ``max_rounds`` raises ``RuntimeError`` (a bug, never a correct run).
    """
    wave.start(done(), bits())
    t = 0
    while True:
        inbox, states = transport.end_round({**wave.state(), "phase": phase})
        t += 1
        step(inbox, transport.round, t)
        transport.note_memory(memory())
        if wave.update(done(), bits(), states):
            return t, wave.bits
        if t > max_rounds:
            raise StageStalledError(f"robot {robot_id}: {phase} did not end within {max_rounds} rounds")
