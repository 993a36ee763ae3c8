"""Distributed consistency stage (Aragüés et al., Secs. III–IV): robots that only talk to
their neighbours detect conflictive sets (Sec. III) and cut them (Alg. 1) until the
association graph is conflict-free (Prop. 4.5).

* :mod:`.robot` — a robot's own state and operations; :mod:`.detection` (Sec. III) and
  :mod:`.resolution` (Alg. 1) — the paper's algorithms, robot side;
* :mod:`.channel` and :mod:`.reliable` — the fault-tolerant protocol for a faulty network
  (message loss, crashed robots, a topology that changes per round);
* :mod:`.protocols` — the two protocols (paper, reliable) behind one interface;
* :mod:`.engine` — the one phase loop, the loop of Prop. 4.5, ``detect_once``;
* :mod:`.centralized` — the union-find check and the baselines; robots never use it.

Robots talk only through :mod:`pipeline.transport`.
"""

from pipeline.consistency.engine import ConsistencyResult, detect_once, resolve_conflicts
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.robot import Robot

__all__ = ["ConsistencyResult", "resolve_conflicts", "detect_once", "ProtocolOptions", "Robot"]
