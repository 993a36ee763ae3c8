"""Robust distributed fusion of landmark estimates (Montijano, Martínez, Sagüés).

* :mod:`pipeline.fusion.consensus` — Metropolis weights, average/ML consensus (eqs. 1–3, 5),
  max-c consensus (eqs. 6–7), RANSAC hypothesis counts;
* :mod:`pipeline.fusion.voting` — distributed ML, static voting (Sec. IV-A) and dynamic
  voting (Sec. IV-B, eqs. 10–14);
* :mod:`pipeline.fusion.flooding` — the exact mode: each track's observations flooded over
  its observer graph, every robot computing the consensus limit; one robot's part in
  :mod:`pipeline.fusion.flood_robot` (``FloodRobot``), its decision in
  :mod:`pipeline.fusion.decision`, its messages on the wire in :mod:`pipeline.fusion.flood_wire`;
* :mod:`pipeline.fusion.protocol` — the logical rounds over the transport (counted, or the
  reliable channel in lockstep on a faulty network);
* :mod:`pipeline.fusion.landmarks` — the stage: tracks, fusion of every track, outliers cut;
* :mod:`pipeline.fusion.local` — each robot's local estimate of the landmarks it observes;
* :mod:`pipeline.fusion.noise` — each robot's keypoint noise, measured from its own two-view
  residuals: the scale of its covariances and gates;
* :mod:`pipeline.fusion.robot` — one robot's fusion over its own endpoint (its own process),
  run round after round by :mod:`pipeline.fusion.robot_loops`;
* :mod:`pipeline.fusion.points` — the fused landmark of each track from the robots' estimates.

May import: the shared words and graphs of the root, :mod:`pipeline.transport` and the
robot side of :mod:`pipeline.consistency` (its reliable channel, protocol options and
termination wave).
"""
