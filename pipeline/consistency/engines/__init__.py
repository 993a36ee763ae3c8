"""The simulator's engines of the consistency stage: all robots of a team in one process.

:mod:`.driver` steps every robot on its inbox (the per-robot engine: the loop of Prop. 4.5,
``resolve_conflicts``, ``detect_once``); :mod:`.batched`, :mod:`.batched_resolution` and
:mod:`.batched_evidence` evaluate the same rounds of all robots at once (property-tested equal
to the per-robot engine).

May import: the robot side of :mod:`pipeline.consistency`, :mod:`pipeline.transport`, the
root's shared words and graphs, :mod:`pipeline.matching`. Robot-side code never imports it.
"""
