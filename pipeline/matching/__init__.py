"""Matching: from images to links between neighbours' features.

Features of one camera (:mod:`.features`), mutual ratio-test matches checked by epipolar
RANSAC on each communication edge (:mod:`.pairs`), neighbours by image similarity for
``knn:K`` graphs (:mod:`.retrieval`), each link's local evidence (:mod:`.link_evidence`),
labelled-landmark matching (:mod:`.landmarks`) and the distributed vote between matchers
(:mod:`.votes`).

May import: the shared words of the root, :mod:`pipeline.inputs`, the graphs
(:mod:`pipeline.association`, :mod:`pipeline.commgraph`) and :mod:`pipeline.transport`.
"""
