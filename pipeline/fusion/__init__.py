"""Robust distributed fusion of landmark estimates (Montijano, Martínez, Sagüés).

* :mod:`pipeline.fusion.consensus` — Metropolis weights, average/ML consensus (eqs. 1–3, 5),
  max-c consensus (eqs. 6–7), RANSAC hypothesis counts;
* :mod:`pipeline.fusion.voting` — distributed ML, static voting (Sec. IV-A) and dynamic
  voting (Sec. IV-B, eqs. 10–14).
"""
