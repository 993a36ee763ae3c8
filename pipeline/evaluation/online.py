"""Scores of a team in motion: pairwise F1 on the image pairs its matching could link.

A moving team's history holds many frames; the true pairs between every two frames of it
(``O(frames²)`` ground-truth calls) would cost more than the run. The score here is the
pairwise score of :mod:`pipeline.evaluation.metrics` restricted to a *scope* of image pairs:
two frames of one robot, or of two robots joined in the formation's communication graph, at
most ``horizon - 1`` steps apart (the pairs the online matcher with window ``horizon`` could
link directly); with a switching topology, joined at the step of the later frame (the step
that matched the pair, :func:`pipeline.matching.pairs.step_pairs`). Implied pairs (two features in one association set) and true pairs are both
counted on the scope only, for every association scored, so online and batch runs are judged
on one scale.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from pipeline.association import AssociationGraph, camera_offsets
from pipeline.types import Links

__all__ = ["scope_pairs", "ScopedTruth"]


def scope_pairs(robot, step, comm_edges, horizon: int, step_edges=None) -> np.ndarray:
    """Image pairs ``(a, b)``, ``a < b``, of the scope (module docstring), ``(P, 2)`` int64.

    ``step_edges``: the edges up at each step (a switching topology), or None: ``comm_edges``
    at every step. A pair is in the scope when its robots talk at the later frame's step.

    Examples
    --------
    >>> scope_pairs([0, 1, 0, 1], [0, 0, 1, 1], [[0, 1]], 1).tolist()
    [[0, 1], [2, 3]]
    >>> len(scope_pairs([0, 1, 0, 1], [0, 0, 1, 1], [[0, 1]], 2))
    6
    >>> scope_pairs([0, 1, 0, 1], [0, 0, 1, 1], [[0, 1]], 2, step_edges=[[[0, 1]], []]).tolist()
    [[0, 1], [0, 2], [1, 3]]
    """
    robot, step = np.asarray(robot, np.int64), np.asarray(step, np.int64)
    n = int(robot.max()) + 1 if len(robot) else 0
    per_step = [comm_edges] * (int(step.max()) + 1 if len(step) else 0) if step_edges is None \
        else list(step_edges)
    near = np.zeros((max(len(per_step), 1), n, n), dtype=bool)
    near[:, np.arange(n), np.arange(n)] = True
    for t, edges in enumerate(per_step):
        for i, j in np.asarray(edges, np.int64).reshape(-1, 2):
            near[t, i, j] = near[t, j, i] = True
    a, b = np.triu_indices(len(robot), k=1)
    later = np.maximum(step[a], step[b])
    ok = near[later, robot[a], robot[b]] & (np.abs(step[a] - step[b]) < horizon)
    return np.stack([a[ok], b[ok]], axis=1).astype(np.int64)


class ScopedTruth:
    """True pairs on a scope of image pairs, to score several associations of one history.

    Parameters
    ----------
    flat : data_synth Formation — every frame as a view (:attr:`data_synth.motion.Sequence.flat`)
    features : list of Features, one per frame
    pairs : (P, 2) image pairs of the scope (:func:`scope_pairs`)
    tol_px : ground-truth tolerance of a good pair
    """

    def __init__(self, flat, features: list, pairs: np.ndarray, tol_px: float = 2.0):
        from data_synth.ground_truth import true_pairs

        self.m = np.array([len(f) for f in features], np.int64)
        self.pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        off = camera_offsets(self.m)
        parts = []
        for a, b in self.pairs.tolist():
            if not self.m[a] or not self.m[b]:
                continue
            p = np.asarray(true_pairs(flat, a, features[a].keypoints, b, features[b].keypoints,
                                      tol_px=tol_px), np.int64).reshape(-1, 2)
            parts.append(np.stack([off[a] + p[:, 0], off[b] + p[:, 1]], axis=1))
        self.truth = np.concatenate(parts) if parts else np.zeros((0, 2), np.int64)
        n = len(self.m)
        self._scope = sp.csr_matrix((np.ones(len(self.pairs)), (self.pairs[:, 0],
                                                                self.pairs[:, 1])), shape=(n, n))

    def scores(self, links: Links) -> dict:
        """Precision, recall, F1 of the pairs ``links`` imply, on the scope."""
        labels = AssociationGraph(self.m, links).components()
        image = np.repeat(np.arange(len(self.m)), self.m)
        N = sp.csr_matrix((np.ones(len(labels)), (labels, image)),
                          shape=(int(labels.max(initial=-1)) + 1, len(self.m)))
        together = (N.T @ N).tocsr()                 # (a, b): pairs of features in one set
        predicted = int(round(together.multiply(self._scope).sum()))
        correct = int((labels[self.truth[:, 0]] == labels[self.truth[:, 1]]).sum())
        n_true = int(len(self.truth))
        precision = correct / predicted if predicted else 0.0
        recall = correct / n_true if n_true else 0.0
        f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
        return {"precision": precision, "recall": recall, "f1": f1,
                "predicted_pairs": predicted, "true_pairs": n_true, "correct_pairs": correct}
