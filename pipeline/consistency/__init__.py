"""Distributed consistency stage (Aragüés et al., Secs. III–IV): robots that only talk to
their neighbours detect conflictive sets (Sec. III) and cut them (Alg. 1) until the
association graph is conflict-free (Prop. 4.5). On a faulty network (message loss, crashed
robots, a topology that changes per round) they run the fault-tolerant protocol of
:mod:`.reliable`. :mod:`.centralized` holds the union-find check and the baselines; robots
never use it.
"""

from pipeline.consistency.engine import ConsistencyResult, resolve_conflicts
from pipeline.consistency.network import Network, NetworkOptions, recurrent_topology
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.consistency.robot import Robot

__all__ = ["ConsistencyResult", "resolve_conflicts", "Network", "NetworkOptions",
           "ProtocolOptions", "recurrent_topology", "Robot"]
