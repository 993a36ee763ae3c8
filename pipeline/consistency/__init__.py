"""Distributed consistency stage (Aragüés et al., Secs. III–IV): robots that only talk to
their neighbours detect conflictive sets (Sec. III) and cut them (Alg. 1) until the
association graph is conflict-free (Prop. 4.5). :mod:`.centralized` holds the union-find
check and the baselines; robots never use it.
"""

from pipeline.consistency.engine import ConsistencyResult, resolve_conflicts
from pipeline.consistency.network import Network, NetworkOptions
from pipeline.consistency.robot import Robot

__all__ = ["ConsistencyResult", "resolve_conflicts", "Network", "NetworkOptions", "Robot"]
