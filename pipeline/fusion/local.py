"""Each robot's local estimate of the landmark of every track it observes (Montijano et al.,
Sec. II: the measurement ``x_i`` with its covariance ``Λ_i`` that the consensus fuses).

A robot triangulates a track from its own keypoint and those of its neighbours in the track
(:func:`triangulate_views`: weighted Gauss-Newton with known poses), robustly over subsets of
the views (:func:`local_estimates`), and reports the estimate with its covariance. The
vectorized stage (:mod:`pipeline.fusion.landmarks`) and one robot alone
(:mod:`pipeline.fusion.robot`) call the same functions.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pipeline.consistency.evidence import far_point

__all__ = ["triangulate_views", "local_estimates", "project", "observing_neighbours",
           "two_view_points", "TwoViewPoints", "pair_agrees", "outlier_pair_tol"]


def _inv3(A):
    """Inverse of (..., 3, 3) matrices by the adjugate, elementwise; det 0 gives inf/nan."""
    a, b, c = A[..., 0, 0], A[..., 0, 1], A[..., 0, 2]
    d, e, f = A[..., 1, 0], A[..., 1, 1], A[..., 1, 2]
    g, h, i = A[..., 2, 0], A[..., 2, 1], A[..., 2, 2]
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c00 + b * c01 + c * c02
    adj = np.stack([np.stack([c00, c * h - b * i, b * f - c * e], -1),
                    np.stack([c01, a * i - c * g, c * d - a * f], -1),
                    np.stack([c02, b * g - a * h, a * e - b * d], -1)], -2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return adj / det[..., None, None]


def _mv3(A, v):
    """``A v`` for (..., 3, 3) and (..., 3), written out."""
    return (A[..., :, 0] * v[..., None, 0] + A[..., :, 1] * v[..., None, 1]
            + A[..., :, 2] * v[..., None, 2])


def project(X, R, t, K, jacobian: bool = True):
    """Pixels and ``2 × 3`` Jacobians of ``X`` (..., 3) in cameras (..., 3, 3)/(..., 3).

    ``jacobian=False``: the Jacobians are not computed (``None`` in their place)."""
    Xc = _mv3(R, X) + t
    p = _mv3(K, Xc)
    z = p[..., 2:3]
    u = p[..., :2] / z
    if not jacobian:
        return u, None, Xc[..., 2]
    # d u / d Xc = (K[:2] - u K[2]) / z ; d Xc / d X = R
    dU = (K[..., :2, :] - u[..., :, None] * K[..., 2:3, :]) / z[..., None]
    return u, dU @ R, Xc[..., 2]


def triangulate_views(uv, views_mask, R, t, K, sigma_px: float = 1.0, iterations: int = 3):
    """Batched multi-view triangulation with first-order covariance.

    Parameters
    ----------
    uv : ndarray, (M, V, 2) — pixel of each candidate view
    views_mask : ndarray, (M, V) bool — views used by each estimate (>= 2 for a solution)
    R, t, K : ndarrays, (M, V, 3, 3), (M, V, 3), (M, V, 3, 3) — cam_from_world and intrinsics
        (or (V, ...) arrays shared by all M estimates)
    sigma_px : float — keypoint noise
    iterations : int — Gauss–Newton steps after the DLT

    Returns
    -------
    X : ndarray, (M, 3)
    cov : ndarray, (M, 3, 3) — ``σ_px² (Σ J_vᵀ J_v)⁻¹``
    ok : ndarray, (M,) bool — finite, covariance positive definite, >= 2 views
    rms_px : ndarray, (M,) — RMS reprojection error over the used views

    Notes
    -----
    The DLT is the smallest right singular vector of the stacked, row-normalized equations;
    the normal matrix ``Σ J_vᵀ J_v`` is checked by its closed-form extreme eigenvalues
    (:func:`pipeline.fusion.consensus.solve_information`'s helper) and inverted by its
    adjugate: every small solve is closed form and vectorized.
    """
    from pipeline.fusion.consensus import extreme_eigenvalues_sym3

    M, V = uv.shape[:2]
    w = views_mask.astype(np.float64)
    xn = _mv3(_inv3(K), np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], -1))
    xn = xn[..., :2] / xn[..., 2:3]
    P = np.concatenate([R, t[..., None]], -1)                         # (M, V, 3, 4)
    rows = np.stack([xn[..., 0:1] * P[..., 2, :] - P[..., 0, :],
                     xn[..., 1:2] * P[..., 2, :] - P[..., 1, :]], -2)  # (M, V, 2, 4)
    rows = rows / np.maximum(np.linalg.norm(rows, axis=-1, keepdims=True), 1e-300)
    A = (rows * w[..., None, None]).reshape(M, -1, 4)
    _, _, Vt = np.linalg.svd(A, full_matrices=False)
    Xh = Vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = Xh[:, :3] / Xh[:, 3:4]
    ok = (views_mask.sum(1) >= 2) & np.isfinite(X).all(1)
    X = np.where(ok[:, None], X, 0.0)
    mask3 = views_mask[..., None]
    for step_no in range(int(iterations) + 1):
        with np.errstate(all="ignore"):
            u, J, _ = project(X[:, None], R, t, K)
        r = np.where(mask3, u - uv, 0.0)
        J = np.where(mask3[..., None], J, 0.0)
        H = np.einsum("mvij,mvik->mjk", J, J)
        g = np.einsum("mvij,mvi->mj", J, r)
        good = ok & np.isfinite(H).all((1, 2)) & np.isfinite(g).all(1)
        Hs = np.where(good[:, None, None], H, np.eye(3))
        lo, hi = extreme_eigenvalues_sym3(Hs)
        good &= lo > 1e-12 * np.maximum(hi, 1e-300)
        ok = good
        Hinv = _inv3(np.where(ok[:, None, None], H, np.eye(3)))
        if step_no == iterations:
            break
        X = np.where(ok[:, None], X - _mv3(Hinv, g), X)
    cov = sigma_px ** 2 * Hinv
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    n_used = np.maximum(views_mask.sum(1), 1)
    rms = np.sqrt((r ** 2).sum((1, 2)) / n_used)
    ok &= np.isfinite(cov).all((1, 2)) & np.isfinite(X).all(1)
    return X, cov, ok, rms


class TwoViewPoints(NamedTuple):
    """The two-view point of every unordered pair of observers of a track (:func:`two_view_points`)."""

    b: np.ndarray    # (U,) int — the track
    lo: np.ndarray   # (U,) int — the pair's robots, lo < hi
    hi: np.ndarray
    X: np.ndarray    # (U, 3) — the point (linear triangulation, Gauss–Newton on the pixels)
    ok: np.ndarray   # (U,) bool — the point is defined (normal matrix positive definite)


def outlier_pair_tol(sigma_px: float, px_thr: float) -> float:
    """Pixels within which two outliers' common point must reproject for their link to stay
    (:mod:`pipeline.fusion.landmarks`, "Outliers leave the landmark"): the pixel gate
    ``‖e‖² / σ² <= χ²_{2,p}`` at the team's noise floor ``sigma_px`` (known to every robot,
    so both ends of a link decide alike; a robot's measured ``σ_i`` is its own)."""
    return float(sigma_px) * float(np.sqrt(px_thr))


def pair_agrees(uv, R, t, K, tol_px: float) -> np.ndarray:
    """Whether each pair of observations can be one point, ``(M,)`` bool.

    ``uv (M, 2, 2)`` the two keypoints, ``R (M, 2, 3, 3)``, ``t (M, 2, 3)``, ``K (M, 2, 3, 3)``
    their cameras, the lower robot id first (so both robots of a pair compute the same bits).
    Their two-view point (:func:`triangulate_views`) in front of both cameras and within
    ``tol_px`` of each keypoint; where it is refused, the point at infinity along their rays
    (:func:`pipeline.consistency.evidence.far_point`: rays without a baseline, the frames of
    a robot standing still, carry no depth and agree exactly when their rays do).
    """
    uv = np.asarray(uv, np.float64).reshape(-1, 2, 2)
    M = len(uv)
    if not M:
        return np.zeros(0, dtype=bool)
    X, _, ok, _ = triangulate_views(uv, np.ones((M, 2), dtype=bool), R, t, K)
    with np.errstate(all="ignore"):
        u, _, z = project(X[:, None], R, t, K, jacobian=False)
        err = np.sqrt(((u - uv) ** 2).sum(-1))
    agree = ok & (z > 0).all(1) & (err <= tol_px).all(1)
    if not agree.all():
        P = K @ np.concatenate([R, t[..., None]], axis=-1)
        rest = np.flatnonzero(~agree)
        agree[rest] = far_point(uv[rest], P[rest], tol_px)
    return agree


def observing_neighbours(observes, adj, robots=None) -> np.ndarray:
    """``nb[b, i, j]``: robots ``i`` and ``j`` are neighbours and both observe track ``b``,
    ``(B, n, n)`` bool; with ``robots`` (``(n,)`` bool) only their rows."""
    nb = observes[:, :, None] & observes[:, None, :] & np.asarray(adj, dtype=bool)[None]
    if robots is not None:
        nb &= np.asarray(robots, dtype=bool)[None, :, None]
    return nb


def two_view_points(kp, nb, Rs, ts, Ks) -> TwoViewPoints:
    """The two-view point of each pair ``(b, i, j)`` of ``nb``, once per unordered pair.

    The point of ``(i, j)`` is the one of ``(j, i)``: it is triangulated in the order
    ``(lo, hi)`` from the same two keypoints and cameras, so a robot holding only its own row
    of ``nb`` gets the bits the simulator gets. Shared by the ``robust`` local estimate
    (:func:`local_estimates`) and the noise measurement (:mod:`pipeline.fusion.noise`).
    """
    # from either robot's row: a robot forming only its own estimates holds only its row
    ub, ui, uj = np.nonzero(np.triu(nb | np.swapaxes(nb, 1, 2), k=1))
    if not len(ub):
        return TwoViewPoints(ub, ui, uj, np.zeros((0, 3)), np.zeros(0, dtype=bool))
    two = np.stack([ui, uj], 1)                                        # (U, 2)
    X, _, ok, _ = triangulate_views(kp[ub[:, None], two], np.ones((len(ub), 2), dtype=bool),
                                    Rs[two], ts[two], Ks[two])
    return TwoViewPoints(ub, ui, uj, X, ok)


def _robust_views(kp, nb, Rs, ts, Ks, sigma_px, px_thr, pairs: TwoViewPoints | None = None):
    """Views of each robot's ``robust`` local estimate, ``(B, n, n)`` bool (without itself).

    For every observing neighbour ``j`` of robot ``i`` the two-view point of ``(i, j)`` is
    triangulated; its support is the set of observing neighbours whose keypoints reproject
    within the pixel gate (robot ``i``'s own keypoint must too). Robot ``i`` keeps the
    support of the pair with the largest support (ties: lowest reprojection RMS) — a local
    RANSAC over its neighbours' keypoints in which its own keypoint is always kept. The
    two-view point of ``(i, j)`` is the one of ``(j, i)`` (robot ``j`` computes it from the
    same two keypoints): it is triangulated once per unordered pair (``pairs``: those of
    :func:`two_view_points` on this ``nb``, when already computed). ``sigma_px`` is each
    robot's keypoint noise ``(n,)``: robot ``i`` tests the reprojections with its own.
    """
    B, n = nb.shape[:2]
    bb, ii, jj = np.nonzero(nb)
    use = np.zeros((B, n, n), dtype=bool)
    if not len(bb):
        return use
    P = len(bb)
    # each unordered pair once: (b, lo, hi) with lo < hi
    if pairs is None:
        pairs = two_view_points(kp, nb, Rs, ts, Ks)
    ub, ui, uj, Xu, oku = pairs
    # the pair of each (b, i, j): the pairs come sorted by (b, lo, hi), so by bisection
    # (not a (B, n, n) table of pair ids)
    pid = np.searchsorted((ub * n + ui) * n + uj,
                          (bb * n + np.minimum(ii, jj)) * n + np.maximum(ii, jj))
    pair = np.zeros((P, n), dtype=bool)
    pair[np.arange(P), ii] = True
    pair[np.arange(P), jj] = True
    # every keypoint of the track against each two-view point, once per unordered pair (the
    # reprojection of a point does not depend on which of its two robots checks it)
    with np.errstate(all="ignore"):
        u, _, z = project(Xu[:, None], Rs[None], ts[None], Ks[None], jacobian=False)  # (U, n)
    e2u = ((u - kp[ub]) ** 2).sum(-1)                                  # px², (U, n)
    e2 = e2u[pid] / sigma_px[ii, None] ** 2
    fits = oku[pid, None] & (z[pid] > 0) & (e2 <= px_thr)
    support = nb[bb, ii] & fits
    own = fits[np.arange(P), ii]
    count = np.where(own, support.sum(1), -1)
    rms = np.sqrt(np.where(support, e2, 0.0).sum(1) / np.maximum(support.sum(1), 1))
    rms = np.where(np.isfinite(rms), rms, np.inf)
    # best pair per robot: largest support, then lowest RMS
    order = np.lexsort((rms, -count, bb * n + ii))
    first = np.ones(P, dtype=bool)
    first[1:] = (bb * n + ii)[order][1:] != (bb * n + ii)[order][:-1]
    best = order[first]
    chosen = support[best]
    # a robot whose own keypoint fits no pair still triangulates with its best pair
    fallback = count[best] < 1
    chosen[fallback] = pair[best[fallback]]
    chosen[np.arange(len(best)), ii[best]] = False
    use[bb[best], ii[best]] = chosen
    return use


def local_estimates(kp, observes, adj, Rs, ts, Ks, sigma_px: float, px_thr: float,
                    local: str = "robust", *, robots=None, pairs: TwoViewPoints | None = None):
    """Each observer's local estimate of each track's landmark (module docstring, ``local=``).

    Parameters
    ----------
    kp : ndarray, (B, n, 2) float64 — keypoint of robot ``i`` in track ``b`` (any finite value
        where it does not observe)
    observes : ndarray, (B, n) bool
    adj : ndarray, (n, n) bool — communication neighbours
    Rs, ts, Ks : ndarrays, (n, 3, 3), (n, 3), (n, 3, 3) — poses and intrinsics (any camera
        with an invertible ``K`` for a robot that is neither in ``robots`` nor a neighbour of
        one: it is never used)
    sigma_px : float or ndarray, (n,) — keypoint noise (pixels), one for all robots or each
        robot's own (:mod:`pipeline.fusion.noise`): robot ``i``'s covariances are
        ``σ_i² (Σ_v J_vᵀ J_v)⁻¹`` and its pixel gate tests ``‖e‖² / σ_i²``
    px_thr : float — pixel gate on the squared reprojection error over ``σ_px²``
    local : ``"robust"``, ``"pair"`` or ``"neighbours"``
    robots : ndarray, (n,) bool or None — form the estimates of these robots only (default
        all). Every row ``(b, i)`` is computed from robot ``i``'s keypoint and camera and its
        observing neighbours' alone, independently of the other rows, so a robot forming
        only its own gets the values the simulator gets for it.
    pairs : TwoViewPoints or None — :func:`two_view_points` of
        ``observing_neighbours(observes, adj, robots)``, if already computed (``robust``)

    Returns
    -------
    X : ndarray, (B, n, 3);  cov : ndarray, (B, n, 3, 3);  estimated : ndarray, (B, n) bool
    """
    B, n = observes.shape
    sigma = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), (n,))
    # observing neighbours of each observer: nb[b, i, j]
    nb = observing_neighbours(observes, adj, robots)
    if local == "pair":
        # ray directions in the world frame; partner = widest angle among observing neighbours
        xn = np.linalg.solve(Ks[None], np.concatenate([kp, np.ones((B, n, 1))], -1)[..., None])
        ray = np.einsum("nji,bnj->bni", Rs, xn[..., 0])  # R^T x
        ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
        cosang = np.einsum("bid,bjd->bij", ray, ray)
        cosang = np.where(nb, cosang, np.inf)
        partner = np.argmin(cosang, axis=-1)
        use = np.zeros((B, n, n), dtype=bool)
        has = nb.any(-1)
        bb, ii = np.nonzero(has)
        use[bb, ii, partner[bb, ii]] = True
    elif local == "robust":
        use = _robust_views(kp, nb, Rs, ts, Ks, sigma, px_thr, pairs)
    else:
        use = nb.copy()
    has_nb = use.any(-1)
    use |= np.eye(n, dtype=bool)[None] & has_nb[..., None]
    est_b, est_i = np.nonzero(has_nb)
    X = np.zeros((B, n, 3))
    cov = np.broadcast_to(np.eye(3), (B, n, 3, 3)).copy()
    estimated = np.zeros((B, n), dtype=bool)
    if len(est_b):
        # robots of one track that chose the same views form the same estimate from the same
        # keypoints and cameras: each distinct (track, views) is triangulated once
        sets = use[est_b, est_i]
        key = np.concatenate([est_b[:, None], np.packbits(sets, axis=1)], 1)
        _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inv = inv.reshape(-1)
        # unit noise here; each robot scales the covariance by its own σ_i²
        Xe, Ce, oke, _ = triangulate_views(kp[est_b[first]], sets[first], Rs, ts, Ks, 1.0)
        Xe, Ce, oke = Xe[inv], Ce[inv] * sigma[est_i, None, None] ** 2, oke[inv]
        X[est_b, est_i] = Xe
        cov[est_b[oke], est_i[oke]] = Ce[oke]
        estimated[est_b, est_i] = oke
    return X, cov, estimated
