"""Pairwise precision / recall / F1 of an association against ground truth.

An association (set of links) is judged by the feature pairs it *implies*: every two features
in one association set are associated, whether or not a link joins them directly (the
transitive closure a multi-view system merges). This is the pairwise score used by CLEAR
(Fathian et al., "CLEAR: A consistent lifting, embedding, and alignment rectification
algorithm for multiview data association", T-RO 2020) and lets the distributed stage and the
centralized baselines be compared on one scale.

Truth: the one-to-one true pairs between the detected keypoints of every camera pair (not just
communication edges), from :func:`data_synth.ground_truth.true_pairs`. Two features of one
camera in one set are always a wrong pair.
"""

from __future__ import annotations

import numpy as np

from pipeline.association import AssociationGraph, association_sets, camera_offsets
from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["association_pairs", "pairwise_scores", "PairwiseTruth", "score_text", "true_pairs_all"]


def association_pairs(features_per_camera, links: Links) -> np.ndarray:
    """All feature pairs implied by ``links``: ``(P, 2)`` global ids, ``a < b``, sorted.

    Complexity: sum over association sets of size^2; vectorized over the sets of one size.
    """
    _, tracks = association_sets(features_per_camera, links)
    if not tracks:
        return np.zeros((0, 2), dtype=np.int64)
    sizes = np.fromiter((len(t) for t in tracks), dtype=np.int64, count=len(tracks))
    members = np.concatenate(tracks).astype(np.int64, copy=False)
    starts = np.cumsum(sizes) - sizes
    parts = []
    for k in np.unique(sizes).tolist():
        rows = members[starts[sizes == k][:, None] + np.arange(k)]   # (sets of size k, k)
        a, b = np.triu_indices(k, k=1)
        parts.append(np.stack([rows[:, a].ravel(), rows[:, b].ravel()], axis=1))
    pairs = np.concatenate(parts)
    pairs.sort(axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _keys(pairs: np.ndarray, m: int) -> np.ndarray:
    return pairs[:, 0].astype(np.int64) * (m + 1) + pairs[:, 1]


def _pairs(pairs, m_total: int, name: str) -> np.ndarray:
    p = np.asarray(pairs)
    if p.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if p.ndim != 2 or p.shape[1] != 2 or p.dtype.kind not in "iu":
        raise InputError(f"{name} pairs: give a (P, 2) array of integer feature ids, got shape "
                         f"{p.shape} of dtype {p.dtype}")
    bad = (p < 0) | (p >= m_total)
    if bad.any():
        k = int(np.flatnonzero(bad.any(axis=1))[0])
        raise InputError(f"{name} pairs: row {k} {p[k].tolist()} names a feature outside "
                         f"0..{m_total - 1} (m_total {m_total})")
    same = np.flatnonzero(p[:, 0] == p[:, 1])
    if same.size:  # a feature is no pair with itself: it would count as a pair found or true
        k = int(same[0])
        raise InputError(f"{name} pairs: row {k} {p[k].tolist()} pairs feature {int(p[k, 0])} "
                         "with itself; give pairs of two different features")
    return p


def _m_total(m_total) -> int:
    """``m_total`` as an int; InputError unless a whole number >= 0 (``None``, ``5.5``)."""
    if isinstance(m_total, bool) or not isinstance(m_total, (int, np.integer)) or m_total < 0:
        raise InputError(f"m_total {m_total!r}: give the number of features, a whole number "
                         ">= 0 (features_per_camera summed)")
    return int(m_total)


def pairwise_scores(predicted: np.ndarray, truth: np.ndarray, m_total: int) -> dict:
    """Precision, recall and F1 of predicted pairs ``(P, 2)`` against true pairs ``(Q, 2)``
    (global feature ids in ``0..m_total - 1``, two different ones; InputError otherwise: a
    pair past ``m_total`` would be counted as another pair, a feature paired with itself as a
    pair)."""
    m_total = _m_total(m_total)
    pk = np.unique(_keys(np.sort(_pairs(predicted, m_total, "predicted"), axis=1), m_total))
    tk = np.unique(_keys(np.sort(_pairs(truth, m_total, "truth"), axis=1), m_total))
    correct = int(np.isin(pk, tk, assume_unique=True).sum())
    precision = correct / len(pk) if len(pk) else 0.0
    recall = correct / len(tk) if len(tk) else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": precision, "recall": recall, "f1": f1,
            "predicted_pairs": int(len(pk)), "true_pairs": int(len(tk)), "correct_pairs": correct}


#: a score printed where it is 0/0 (its value in a report stays the 0.0 it is computed as)
NOT_DEFINED = "–"


def score_text(scores: dict, key: str) -> str:
    """``scores[key]`` (``precision``, ``recall`` or ``f1`` of :func:`pairwise_scores` or
    :meth:`PairwiseTruth.scores`) as a table prints it, ``'–'`` where it is 0/0 and so not a
    measurement: precision without a predicted pair, recall without a true pair, F1 without
    either.

    Examples
    --------
    >>> score_text({"precision": 0.5, "recall": 0.25, "f1": 1 / 3, "predicted_pairs": 2,
    ...             "true_pairs": 4}, "f1")
    '0.333'
    >>> none = {"precision": 0.0, "recall": 0.0, "f1": 0.0, "predicted_pairs": 0, "true_pairs": 0}
    >>> [score_text(none, k) for k in ("precision", "recall", "f1")]
    ['–', '–', '–']
    >>> score_text(dict(none, true_pairs=3), "recall"), score_text(dict(none, true_pairs=3), "f1")
    ('0.000', '0.000')
    """
    undefined = {"precision": scores["predicted_pairs"] == 0,
                 "recall": scores["true_pairs"] == 0,
                 "f1": scores["predicted_pairs"] == 0 and scores["true_pairs"] == 0}[key]
    return NOT_DEFINED if undefined else f"{scores[key]:.3f}"


class PairwiseTruth:
    """The true pairs of one input, to score many associations of it (the links before and
    after each stage, each baseline) without listing the pairs they imply.

    ``PairwiseTruth(truth, m_total).scores(m, links)`` equals
    ``pairwise_scores(association_pairs(m, links), truth, m_total)``: an association set of
    ``k`` features implies ``k (k - 1) / 2`` pairs, and a true pair is implied iff its two
    features lie in one connected component of ``links``. ``O(m + L + Q)`` per call instead
    of sorting every implied pair.

    Parameters
    ----------
    truth : ndarray, (Q, 2) int — true pairs of global feature ids, either order
    m_total : int — number of features

    Examples
    --------
    >>> import numpy as np
    >>> from pipeline.types import Links
    >>> chain = Links([0, 1], [0, 0], [1, 2], [0, 0])   # 0:0 - 1:0 - 2:0
    >>> s = PairwiseTruth(np.array([[2, 0], [1, 2]]), 3).scores([1, 1, 1], chain)
    >>> s["predicted_pairs"], s["correct_pairs"], s["recall"]
    (3, 2, 1.0)
    """

    def __init__(self, truth: np.ndarray, m_total: int):
        self.m_total = _m_total(m_total)
        # checked as pairwise_scores checks it: a pair past m_total wrapped into another pair
        keys = np.unique(_keys(np.sort(_pairs(truth, self.m_total, "truth").astype(np.int64),
                                       axis=1), self.m_total))
        a, b = keys // (self.m_total + 1), keys % (self.m_total + 1)
        # only pairs of two distinct existing features can ever be implied by links
        can = (a != b) & (a >= 0) & (b < self.m_total)
        self.n_true = int(len(keys))
        self._a, self._b = a[can], b[can]

    def scores(self, features_per_camera, links: Links,
               graph: AssociationGraph | None = None) -> dict:
        """The dict of :func:`pairwise_scores` for the pairs implied by ``links``
        (``graph``: their :class:`AssociationGraph`, when the caller has it)."""
        if graph is None:
            graph = AssociationGraph(features_per_camera, links)
        labels = graph.components()
        if labels.size != self.m_total:
            raise ValueError(f"PairwiseTruth of {self.m_total} features scored on "
                             f"{labels.size} features")
        sizes = np.bincount(labels) if labels.size else np.zeros(0, dtype=np.int64)
        predicted = int((sizes * (sizes - 1) // 2).sum())
        correct = int((labels[self._a] == labels[self._b]).sum())
        precision = correct / predicted if predicted else 0.0
        recall = correct / self.n_true if self.n_true else 0.0
        f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
        return {"precision": precision, "recall": recall, "f1": f1,
                "predicted_pairs": predicted, "true_pairs": self.n_true,
                "correct_pairs": correct}


def true_pairs_all(formation, features, tol_px: float = 2.0) -> np.ndarray:
    """True pairs between detected keypoints of every camera pair, ``(Q, 2)`` global ids."""
    from data_synth.ground_truth import true_pairs

    m = [len(f) for f in features]
    off = camera_offsets(m)
    parts = []
    for i in range(len(features)):
        for j in range(i + 1, len(features)):
            if not m[i] or not m[j]:
                continue
            p = np.asarray(true_pairs(formation, i, features[i].keypoints, j,
                                      features[j].keypoints, tol_px=tol_px), dtype=np.int64)
            if len(p):
                parts.append(np.stack([p[:, 0] + off[i], p[:, 1] + off[j]], axis=1))
    return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.int64)
