"""Evaluation: centralized code that judges the robots' results, never used by them.

Good, spurious and missing links of a rendered formation (:mod:`.links`) and of photographs
with known homographies (:mod:`.truth`), pairwise precision / recall (:mod:`.metrics`), the
truth-aware oracle (:mod:`.oracle`), the pycolmap check of the tracks (:mod:`.triangulation`),
warnings of a photo run (:mod:`.flags`) and every section of ``report.json`` (:mod:`.report`).

May import: the shared words and graphs of the root, :mod:`pipeline.inputs`,
:mod:`pipeline.colmap`, :mod:`pipeline.matching` and :mod:`pipeline.consistency` (its
centralized baselines and rule registry); never a runner, the stage chain or the team.
"""
