"""Each robot's keypoint noise, measured from its own tracks: the scale of the fusion gates.

The fusion stage's covariances ``Λ_i = σ_i² (Σ_v J_vᵀ J_v)⁻¹`` (:mod:`pipeline.fusion.local`),
its vote (Montijano et al., the chi-square test of eqs. 12–13 on ``Λ_i``) and its pixel check
(``‖e‖² / σ_i² <= χ²_{2,p}``) all rest on the keypoint noise ``σ_i``. A fixed ``σ`` suits
rendered formations and not photographs, whose noise differs from data set to data set and
from camera to camera (poses from a reconstruction, viewpoint, blur). So each robot measures
its own, from what it already holds before the fusion starts: its keypoints and those its
observing neighbours sent in the setup message, with their poses and intrinsics.

The measurement (``noise="measured"``)
--------------------------------------
* **Residuals.** For every track ``b`` robot ``i`` observes and every observing neighbour
  ``j``, the two-view point of the keypoints of ``i`` and ``j`` (linear triangulation and
  Gauss–Newton on the pixel error, :func:`pipeline.fusion.local.triangulate_views`, the
  points the ``robust`` local estimate is built from) leaves the residual
  ``d_bij = sqrt(‖u_i(X) − x_i‖² + ‖u_j(X) − x_j‖²)``. It is the distance of the keypoint
  pair to the pairs the two poses allow: one degree of freedom (Hartley and Zisserman,
  optimal two-view triangulation), so under isotropic Gaussian keypoint noise of standard
  deviation ``σ`` in both images ``d ~ |N(0, σ²)|`` to first order, and the robust estimate
  would be ``median(d) / 0.6745``.
* **The law.** Keypoint errors are heavier-tailed than Gaussian (measured on the two-view
  residuals: the 90 % quantile over the median is 3.8 on Graffiti and 4.1 on formation ``d``,
  2.4 for a Gaussian and 3.3 for an exponential law). The project models the epipolar error
  of good links as exponential with scale ``β = median(d) / ln 2``
  (:mod:`pipeline.matching.link_evidence`); the same law here.
* **The scale of the gates.** The gates are chi-square tests on Gaussian covariances, so
  robot ``i`` takes the Gaussian ``σ_i`` whose ``p``-quantile of ``d`` is the exponential
  law's: ``σ_i sqrt(χ²_{1,p}) = β_i ln(1 / (1 − p))``, i.e.
  ``σ_i = median_i(d) · ln(1 / (1 − p)) / (ln 2 · sqrt(χ²_{1,p}))`` (2.58 × the median at
  ``p = 0.99``, the vote's confidence). The gates then pass the fraction ``p`` of the
  robot's good residuals under the measured law, not under a Gaussian fitted to its core
  (``median / 0.6745``: 0.4–0.9 px on Graffiti, whose gates cut 103 good links on the
  complete graph where the fixed 1 px cut 67; both figures of an earlier version of the
  stage, before the cut rule of :mod:`pipeline.fusion.landmarks`, "Outliers leave the
  landmark").
* **The floor.** ``σ_i >= sigma_px`` (1 px by default): the gates decide whether an
  observation is the landmark's point, not how well it is localised. Rendered formations
  measure ``σ_i`` = 0.10–0.15 px by the rule above while right matches there lie up to 2 px
  apart (the tolerance of their ground truth and of the evidence rule's merge radius): gates
  at that scale cut 189 good links on formation ``d`` (640x480, seed 0) where 1 px cut 10,
  with the same earlier version of the stage (today 1 px cuts 1 there:
  ``run-formations --resolution evidence``).
  Below the floor the measured noise is not used; above it, it is (Graffiti, complete graph:
  1.0–1.7 px, ``fusion.robot_sigma_px`` of the reports ``python bench/graffiti_truth.py``
  saves; Sceaux at full size: up to 2.8 px).
* **Too few residuals.** A robot with fewer than :data:`MIN_RESIDUALS` finite residuals
  (no observing neighbour, or a handful of tracks) keeps the floor.
* **Who knows what.** Robot ``i`` uses its own ``σ_i`` for everything it decides: its local
  estimate's covariance, which neighbours' keypoints support it, its vote and its pixel check.
  Nothing is sent: the neighbours' keypoints and cameras are those of the setup message.
  The two-view point of ``(i, j)`` is the one of ``(j, i)`` (triangulated in the order
  ``lo, hi``), so a robot computing only its own ``σ_i`` gets the bits the simulator gets.

``noise="fixed"``: every robot uses ``sigma_px`` (the stage as it ran before).
"""

from __future__ import annotations

import numpy as np
from scipy.special import gammaincinv

from pipeline.errors import InputError
from pipeline.fusion.local import (
    TwoViewPoints,
    observing_neighbours,
    project,
    two_view_points,
)

__all__ = ["NOISE_MODES", "MIN_RESIDUALS", "two_view_residuals", "gate_scale", "robot_noise"]

NOISE_MODES = ("measured", "fixed")
#: fewer finite two-view residuals than this: the robot keeps the floor ``sigma_px``
MIN_RESIDUALS = 5


def two_view_residuals(kp, nb, Rs, ts, Ks, pairs: TwoViewPoints | None = None):
    """The two-view residual of every pair of observers of a track, once per unordered pair.

    Parameters
    ----------
    kp : ndarray, (B, n, 2) — keypoint of robot ``i`` in track ``b``
    nb : ndarray, (B, n, n) bool — ``nb[b, i, j]``: ``i`` and ``j`` are neighbours and both
        observe ``b`` (a robot that forms only its own row may hold only that row)
    Rs, ts, Ks : ndarrays, (n, 3, 3), (n, 3), (n, 3, 3)
    pairs : TwoViewPoints or None — :func:`pipeline.fusion.local.two_view_points` of ``nb``,
        if already computed (the ``robust`` local estimate triangulates the same pairs)

    Returns
    -------
    b, lo, hi : ndarrays, (U,) int — the pair's track and robots (``lo < hi``)
    d : ndarray, (U,) float64 — ``sqrt`` of the summed squared reprojection errors (px) of
        the two keypoints at their two-view point
    ok : ndarray, (U,) bool — the point is defined and in front of both cameras
    """
    ub, ui, uj, X, ok = two_view_points(kp, nb, Rs, ts, Ks) if pairs is None else pairs
    if not len(ub):
        return ub, ui, uj, np.zeros(0), np.zeros(0, dtype=bool)
    two = np.stack([ui, uj], 1)
    uv = kp[ub[:, None], two]
    with np.errstate(all="ignore"):
        u, _, z = project(X[:, None], Rs[two], ts[two], Ks[two], jacobian=False)
        d = np.sqrt(((u - uv) ** 2).sum((-1, -2)))
    ok = ok & (z > 0).all(1) & np.isfinite(d)
    return ub, ui, uj, d, ok


def gate_scale(median_px, p: float):
    """The Gaussian ``σ`` whose ``p``-quantile of a one-dof residual equals that of the
    exponential law with median ``median_px`` (module docstring, "The scale of the gates").

    Examples
    --------
    >>> round(float(gate_scale(1.0, 0.99)), 3)
    2.579
    """
    chi2_1 = 2.0 * gammaincinv(0.5, p)   # χ²_{1,p}
    return np.asarray(median_px) * np.log(1.0 / (1.0 - p)) / (np.log(2.0) * np.sqrt(chi2_1))


def robot_noise(kp, observes, adj, Rs, ts, Ks, sigma_px: float = 1.0, p: float = 0.99,
                noise: str = "measured", *, robots=None,
                pairs: TwoViewPoints | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each robot's keypoint noise ``σ_i`` (pixels) for its covariances and gates.

    Parameters
    ----------
    kp, observes, adj, Rs, ts, Ks : as :func:`pipeline.fusion.local.local_estimates`
    sigma_px : float — the floor (``"measured"``) or every robot's noise (``"fixed"``)
    p : float — the gates' confidence
    noise : ``"measured"`` or ``"fixed"``
    robots : ndarray, (n,) bool or None — measure these robots only (default all); the others
        get ``sigma_px``
    pairs : TwoViewPoints or None — :func:`pipeline.fusion.local.two_view_points` of
        ``observing_neighbours(observes, adj, robots)``, if already computed

    Returns
    -------
    sigma : ndarray, (n,) float64 — ``max(sigma_px, gate_scale(median_i(d), p))``, or
        ``sigma_px`` for a robot with fewer than :data:`MIN_RESIDUALS` residuals
    residuals : ndarray, (n,) int — how many residuals each robot's median was taken over
    """
    if noise not in NOISE_MODES:
        raise InputError(f"noise must be one of {NOISE_MODES}, got {noise!r}")
    if not sigma_px > 0:
        raise InputError(f"sigma_px must be > 0, got {sigma_px}")
    B, n = observes.shape
    sigma = np.full(n, float(sigma_px))
    count = np.zeros(n, dtype=np.int64)
    if noise == "fixed" or not B:
        return sigma, count
    mine = np.ones(n, dtype=bool) if robots is None else np.asarray(robots, dtype=bool)
    # (given the pairs, the (B, n, n) table of observing neighbours is not needed)
    nb = observing_neighbours(observes, adj, mine) if pairs is None else None
    _, lo, hi, d, ok = two_view_residuals(kp, nb, Rs, ts, Ks, pairs)
    # each residual counts for both its robots; the median of each robot's, sorted by value
    who = np.concatenate([lo[ok], hi[ok]])
    val = np.concatenate([d[ok], d[ok]])
    keep = mine[who]
    who, val = who[keep], val[keep]
    order = np.lexsort((val, who))
    val = val[order]
    count = np.bincount(who, minlength=n).astype(np.int64)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    has = count >= MIN_RESIDUALS
    mid = 0.5 * (val[(start + (count - 1) // 2)[has]] + val[(start + count // 2)[has]])
    sigma[has] = np.maximum(float(sigma_px), gate_scale(mid, p))
    return sigma, count
