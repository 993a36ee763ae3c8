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

The names below are imported on first use (PEP 562), so that a robot process that imports
one robot-side module (e.g. :mod:`.termination`) does not load the simulator's driver and
its dependencies.
"""

import importlib

__all__ = ["ConsistencyResult", "resolve_conflicts", "detect_once", "ProtocolOptions", "Robot",
           "RESOLUTIONS", "DEFAULT_RESOLUTION"]

#: the resolution rules: ``paper`` (Alg. 1) and ``evidence`` (:mod:`.evidence`)
RESOLUTIONS = ("paper", "evidence")
#: the rule every entry point uses unless told otherwise (the Python API, the commands, a
#: TEAM.json without ``resolution``); ``run-formations`` reproduces the paper's tables with
#: ``paper``
DEFAULT_RESOLUTION = "evidence"

_HOME = {"ConsistencyResult": "engine", "resolve_conflicts": "engine", "detect_once": "engine",
         "ProtocolOptions": "protocols", "Robot": "robot"}


def __getattr__(name: str):
    if name in _HOME:
        return getattr(importlib.import_module(f"{__name__}.{_HOME[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *__all__])
