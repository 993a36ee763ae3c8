"""Per-link evidence for the evidence-aware resolution: what the two robots of a link hold.

Matching (Aragüés et al., Sec. V-B) runs between the two neighbours of a communication edge, so
both robots of a link hold its Lowe ratio and its Sampson error under the edge's RANSAC
epipolar model; where camera poses are known (rendered formations, robots that localise),
they can also exchange their poses and measure the link against the *known* epipolar
geometry. This module turns that into one local log-likelihood ratio per link,
``good`` vs ``spurious`` (positive: rather good). The third piece of evidence, triangle
support, needs the links of third cameras and is added by the robots of a conflictive set
(:mod:`pipeline.consistency.evidence`).

Models (stated, not fitted to any data set):

* Epipolar error ``e`` (pixels). Good links: exponential (a Laplace error folded at 0; the
  keypoint noise is heavy-tailed, which a half-normal would turn into confident cuts of good
  links) with scale ``β`` estimated per communication edge from that edge's own links,
  ``β = median(e) / ln 2`` (the edge's links are mostly good, so the median is robust to the
  spurious ones; floored at :data:`MIN_SCALE_PX`). Spurious links: uniform on ``[0, T]``,
  ``T`` the RANSAC inlier threshold. ``llr_geo = log(T / β) − e / β``. With known poses ``e`` is the
  Sampson error under ``F = K_j^{-T} [t_ji]_× R_ji K_i^{-1}`` from the poses, otherwise the
  RANSAC model's.
* Lowe ratio ``ρ``: densities ``∝ 1 − ρ`` for good and ``∝ ρ`` for spurious matches on
  ``[0, 1]`` (the shapes of Lowe 2004, Fig. 11), ``llr_ratio = log((1 − ρ) / ρ)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import InputError
from pipeline.matching.pairs import sampson_error_px
from pipeline.types import Links, PairMatches

__all__ = ["LinkEvidence", "link_evidence", "edge_evidence", "geometric_llr", "ratio_llr", "pose_fundamental",
           "MIN_SCALE_PX"]

#: smallest epipolar error scale (pixels) a good link is assumed to have
MIN_SCALE_PX = 0.05
#: Lowe ratios are clipped to ``[RATIO_EPS, 1 - RATIO_EPS]`` before the log-odds
RATIO_EPS = 0.01
#: beyond the clip the log-odds still fall by this much per unit of ratio (:func:`ratio_llr`):
#: only the order of the clipped links, far below every other evidence term
RATIO_TIE_SLOPE = 1e-3


@dataclass
class LinkEvidence:
    """Evidence of every link, in the order of the ``Links`` it was built for.

    Attributes
    ----------
    ratio : ndarray, (L,) float64 — Lowe ratio (lower is better)
    epipolar_error : ndarray, (L,) float64 — Sampson error (px) under the edge's RANSAC model
    pose_error : ndarray, (L,) float64 — Sampson error (px) under the known poses; ``nan``
        when the poses are unknown
    weight : ndarray, (L,) float64 — local log-likelihood ratio ``llr_geo + llr_ratio``
        (see the module docstring); the robots add triangle support to it
    """

    ratio: np.ndarray
    epipolar_error: np.ndarray
    pose_error: np.ndarray
    weight: np.ndarray

    def subset(self, mask) -> LinkEvidence:
        return LinkEvidence(self.ratio[mask], self.epipolar_error[mask], self.pose_error[mask],
                            self.weight[mask])

    @staticmethod
    def from_quality(links: Links) -> LinkEvidence:
        """Evidence from ``Links.quality`` alone (``1 − ratio``, e.g. a user's links file)."""
        ratio = np.maximum(1.0 - links.quality, 0.0)
        nan = np.full(len(links), np.nan)
        return LinkEvidence(ratio, nan, nan.copy(), ratio_llr(ratio))


def ratio_llr(ratio: np.ndarray) -> np.ndarray:
    """``log((1 − ρ) / ρ)``, ``(L,)`` — the Lowe-ratio log-likelihood ratio.

    ``ρ`` is clipped to ``[RATIO_EPS, 1 − RATIO_EPS]``; beyond the clip the value keeps falling
    by :data:`RATIO_TIE_SLOPE` per unit of ``ρ``, so the log-odds stay strictly decreasing in
    ``ρ``. A ratio of 1 or more is real input: an assignment (the Hungarian matching of the
    labelled benchmarks, ``run-landmarks --ratio none``) may pair a feature with another than
    its nearest neighbour, ``ρ = d / d_alt > 1``. On the warped copies of CMU hotel of
    ``bench/multiway.py`` 40–53 % of the links had ``ρ ≥ 1 − RATIO_EPS``, 54–74 % of them
    good; a flat value left their order in the greedy merge to the feature ids instead of
    the descriptor distances (README, "Multi-way matching")."""
    r = np.asarray(ratio, dtype=np.float64)
    c = np.clip(r, RATIO_EPS, 1.0 - RATIO_EPS)
    return np.log1p(-c) - np.log(c) - RATIO_TIE_SLOPE * (r - c)


def geometric_llr(error: np.ndarray, edge: np.ndarray, threshold_px: float) -> np.ndarray:
    """Exponential (scale per edge) vs uniform on ``[0, T]`` log-likelihood ratio, ``(L,)``.

    Parameters
    ----------
    error : ndarray, (L,) — epipolar error in pixels (``nan``: no evidence, LLR 0)
    edge : ndarray, (L,) int — communication edge of each link (β is estimated per edge)
    threshold_px : float — ``T``, the RANSAC inlier threshold
    """
    error = np.asarray(error, dtype=np.float64)
    out = np.zeros(error.shape[0])
    ok = np.isfinite(error)
    if not ok.any():
        return out
    edges, inv = np.unique(np.asarray(edge)[ok], return_inverse=True)
    e = error[ok]
    beta = np.array([np.median(e[inv == k]) for k in range(edges.size)]) / np.log(2.0)
    beta = np.maximum(beta, MIN_SCALE_PX)[inv]
    out[ok] = np.log(threshold_px / beta) - e / beta
    return out


def pose_fundamental(K_i, R_i, t_i, K_j, R_j, t_j) -> np.ndarray:
    """``F`` with ``x_jᵀ F x_i = 0`` from two ``cam_from_world`` poses, ``(3, 3)``."""
    R_ji = R_j @ R_i.T
    t_ji = t_j - R_ji @ t_i
    tx = np.array([[0.0, -t_ji[2], t_ji[1]], [t_ji[2], 0.0, -t_ji[0]], [-t_ji[1], t_ji[0], 0.0]])
    return np.linalg.inv(K_j).T @ tx @ R_ji @ np.linalg.inv(K_i)


def link_evidence(matches: list[PairMatches], links: Links, views=None, features=None,
                  threshold_px: float = 1.0) -> LinkEvidence:
    """Evidence of ``links = Links.from_matches(matches)``, ``(L,)`` each.

    Parameters
    ----------
    matches : list[PairMatches] — the per-edge matching results behind ``links``
    links : Links, (L,)
    views : list[View] or None — poses used where every view has one
    features : list[Features] or None — keypoints (needed with ``views``)
    threshold_px : float — the RANSAC inlier threshold matching used

    Raises
    ------
    InputError
        ``links`` is not the concatenation of ``matches``.
    """
    parts = [m for m in matches if len(m.pairs)]
    L = len(links)
    if sum(len(m.pairs) for m in parts) != L:
        raise InputError(f"{L} links but the matches hold {sum(len(m.pairs) for m in parts)}; "
                         "build the links with Links.from_matches(matches)")
    if not L:
        z = np.zeros(0)
        return LinkEvidence(z, z.copy(), z.copy(), z.copy())
    ratio = np.concatenate([m.ratio for m in parts]).astype(np.float64)
    epi = np.concatenate([m.epipolar_error for m in parts]).astype(np.float64)
    edge = np.repeat(np.arange(len(parts)), [len(m.pairs) for m in parts])
    pose = np.full(L, np.nan)
    if views is not None and features is not None and all(
            v.R is not None and v.t is not None for v in views):
        for k, m in enumerate(parts):
            sel = edge == k
            vi, vj = views[m.i], views[m.j]
            F = pose_fundamental(vi.K, vi.R, vi.t, vj.K, vj.R, vj.t)
            pose[sel] = sampson_error_px(F, features[m.i].keypoints[links.feat_i[sel]],
                                         features[m.j].keypoints[links.feat_j[sel]])
    geo = np.where(np.isfinite(pose), pose, epi)
    weight = geometric_llr(geo, edge, threshold_px) + ratio_llr(ratio)
    return LinkEvidence(ratio, epi, pose, weight)


def edge_evidence(pm: PairMatches, keypoints_i: np.ndarray, keypoints_j: np.ndarray,
                  pose_i=None, pose_j=None, threshold_px: float = 1.0) -> LinkEvidence:
    """Evidence of the links of one communication edge, as its two robots compute it.

    The per-edge form of :func:`link_evidence` (the same models, the scale ``β`` from this
    edge's own links), for a robot that holds only its own keypoints and what its neighbour
    sent it: ``pm`` (``pm.pairs[:, 0]`` indexes robot ``pm.i``'s keypoints, ``[:, 1]``
    robot ``pm.j``'s), both keypoint arrays ``(m_i, 2)``, ``(m_j, 2)`` and, where both poses
    are known, ``pose_i = (K, R, t)`` and ``pose_j``. On every edge of a run where all poses
    are known, or none, it gives :func:`link_evidence`'s values bit for bit.

    Returns
    -------
    LinkEvidence, each array ``(len(pm.pairs),)``
    """
    L = len(pm.pairs)
    ratio = np.asarray(pm.ratio, dtype=np.float64).reshape(L)
    epi = np.asarray(pm.epipolar_error, dtype=np.float64).reshape(L)
    pose = np.full(L, np.nan)
    if L and pose_i is not None and pose_j is not None:
        (Ki, Ri, ti), (Kj, Rj, tj) = pose_i, pose_j
        F = pose_fundamental(Ki, Ri, ti, Kj, Rj, tj)
        pairs = np.asarray(pm.pairs).reshape(-1, 2)
        pose[:] = sampson_error_px(F, keypoints_i[pairs[:, 0]], keypoints_j[pairs[:, 1]])
    geo = np.where(np.isfinite(pose), pose, epi)
    weight = geometric_llr(geo, np.zeros(L, dtype=np.int64), threshold_px) + ratio_llr(ratio)
    return LinkEvidence(ratio, epi, pose, weight)
