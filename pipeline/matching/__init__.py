"""Matching: from images to links between neighbours' features.

The names of its variants (:mod:`.methods`: feature methods, pair matchers), features of one
camera (:mod:`.features`, one detector per method), mutual ratio-test matches checked by epipolar
RANSAC on each communication edge (:mod:`.pairs`), neighbours by image similarity for
``knn:K`` graphs (:mod:`.retrieval`), each link's local evidence (:mod:`.link_evidence`),
labelled-landmark matching (:mod:`.landmarks`) and the distributed vote between matchers
(:mod:`.votes`).

May import: the shared words of the root, :mod:`pipeline.inputs`, the graphs
(:mod:`pipeline.association`, :mod:`pipeline.commgraph`) and :mod:`pipeline.transport`.
"""
