"""Distributed consistency stage (Aragüés et al., Secs. III–IV): robots that only talk to
their neighbours detect conflictive sets (Sec. III) and cut them by a resolution rule (the
evidence rule by default, :data:`.rules.DEFAULT_RESOLUTION`; ``paper``: Alg. 1) until the
association graph is conflict-free (Prop. 4.5).

Robot side (what a robot runs, in the simulator or in its own process):

* :mod:`.robot` — a robot's own state and operations; :mod:`.detection` (Sec. III) and
  :mod:`.resolution` (Alg. 1) — the paper's algorithms; :mod:`.evidence` — the
  evidence-aware resolution rule, after the bounded label flooding of :mod:`.setlists` (sets
  beyond its bundle budget merged by :mod:`.sync`); :mod:`.keys` — sorted-key helpers;
* :mod:`.channel` and :mod:`.reliable` — the fault-tolerant protocol for a faulty network
  (message loss, crashed robots, a topology that changes per round);
* :mod:`.protocols` — the two protocols (paper, reliable) behind one interface;
* :mod:`.termination` — one robot alone runs the phases and ends each by the termination wave.

Around the robots:

* :mod:`.rules` — the registry of resolution rules (the one list of their names, and
  ``DEFAULT_RESOLUTION``, the rule every entry point runs unless told otherwise);
* :mod:`.engines` — the simulator: the per-robot driver (the loop of Prop. 4.5,
  ``resolve_conflicts``, ``detect_once``), the one phase loop, the batched engines;
* :mod:`.result` and :mod:`.linklog` — what the stage did to every link, from the robots' logs;
* :mod:`.centralized` — the union-find check and the baselines; robots never use it.

Robots talk only through :mod:`pipeline.transport`. May import: the shared words and graphs
of the root, :mod:`pipeline.transport` and :mod:`pipeline.matching` (link evidence); the robot
side never imports :mod:`.engines`.

The names below are imported on first use (PEP 562), so that a robot process that imports
one robot-side module (e.g. :mod:`.termination`) does not load the simulator's driver and
its dependencies.
"""

import importlib

__all__ = ["ConsistencyResult", "resolve_conflicts", "detect_once", "ProtocolOptions", "Robot"]

_HOME = {"ConsistencyResult": "result", "resolve_conflicts": "engines.driver",
         "detect_once": "engines.driver",
         "ProtocolOptions": "protocols", "Robot": "robot"}


def __getattr__(name: str):
    if name in _HOME:
        return getattr(importlib.import_module(f"{__name__}.{_HOME[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *__all__])
