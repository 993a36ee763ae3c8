"""Local data association between communication neighbours (Aragüés et al., Sec. II and V-B).

Each robot matches its features only with those of its neighbours in the communication graph
``G_com`` (Sec. II: robot ``i`` "can compute the data association between its own set S_i and
the sets of its neighbors S_j, with j ∈ N_i"); a pair of robots that cannot communicate never
gets an association block (``W_ij = 0``, eq. 3).

For every communication edge ``(i, j)``, ``i < j``:

1. putative matches: mutual nearest neighbours in descriptor space with Lowe's ratio test,
2. the epipolar constraint with RANSAC (Sec. V-B, ref. [13]) — here ``cv2.USAC_MAGSAC`` on the
   essential matrix when both cameras are calibrated, on the fundamental matrix otherwise.

With ``matcher="colmap"`` (the photographs' default) both steps are COLMAP's own
(:func:`pipeline.colmap.sift.match_pairs`: mutual nearest neighbours with its ratio test, then
its two-view geometry with its 4 px threshold and 15 inliers at least), on the same
communication edges only; each link's Lowe ratio and Sampson error are then computed here as
for the OpenCV matcher, for the evidence of :mod:`pipeline.matching.link_evidence`.

The result is one one-to-one association ``A_ij`` per undirected edge (Assumption 2.2), stored
once with ``i < j``; ``A_ji = A_ijᵀ`` is implied (Assumption 2.3), ``A_ii = I`` (Assumption 2.1)
is added by :mod:`pipeline.association`.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from pipeline.commgraph import check_comm_edges
from pipeline.errors import InputError
from pipeline.matching.methods import MATCHERS
from pipeline.types import Features, PairMatches, View

__all__ = ["mutual_ratio_matches", "epipolar_filter", "sampson_error_px", "lowe_ratios",
           "match_pair", "match_edges", "photo_threshold_px", "MIN_MATCHES", "MATCHERS",
           "COLMAP_MIN_INLIERS", "COLMAP_MAX_ERROR_PX", "check_matcher", "COLMAP_MATCHER_FEATURES", "step_pairs"]

#: COLMAP's defaults for its verification: ``TwoViewGeometryOptions.min_num_inliers`` and
#: ``ransac.max_error`` (pixels)
COLMAP_MIN_INLIERS, COLMAP_MAX_ERROR_PX = 15, 4.0

#: fewest matches an association may have; below this it is left empty (USAC needs >= 7 points)
MIN_MATCHES = 8

#: image side (pixels) per pixel of epipolar threshold in :func:`photo_threshold_px`
PX_PER_THRESHOLD_PX = 800


def photo_threshold_px(width: int, height: int) -> float:
    """Epipolar inlier threshold for a photograph: 1 px per 800 px of its longest side, >= 1.

    COLMAP verifies with 4 px (``TwoViewGeometry.max_error``) at its default 3200 px image
    size; the threshold is scaled with the image so that it bounds the same fraction of the
    image: 1 px at 640-800 px (the rendered formations' own 1 px), 2 px at 1600 px, 4 px at
    3200 px. Real lenses are not pinholes: a fixed 1 px at 1600 px rejects the true matches
    near the borders of a slightly distorted photograph.

    Examples
    --------
    >>> photo_threshold_px(640, 480), photo_threshold_px(1600, 1200), photo_threshold_px(3200, 2400)
    (1.0, 2.0, 4.0)
    """
    return max(1.0, max(int(width), int(height)) / PX_PER_THRESHOLD_PX)


# --------------------------------------------------------------------------- putative matches


def _distance_matrix(d_i: np.ndarray, d_j: np.ndarray, squared: bool = False) -> np.ndarray:
    """Exact descriptor distances, ``(N_i, N_j)`` float32 (L2, or Hamming for uint8).

    One matrix serves both matching directions, so the mutual test costs one product. With
    ``squared`` the L2 distances are left squared (the caller takes the square root of the few
    it needs: same values, one pass over the matrix fewer); Hamming distances are never squared.
    """
    if d_i.dtype == np.uint8:
        # Hamming: popcount(a xor b), 64 bits at a time (exact; faster than unpacked-bit BLAS
        # products, measured in bench/foundation.py)
        pad = ((0, 0), (0, (-d_i.shape[1]) % 8))
        a = np.ascontiguousarray(np.pad(d_i, pad)).view(np.uint64)
        b = np.ascontiguousarray(np.pad(d_j, pad)).view(np.uint64)
        dist = np.zeros((len(a), len(b)), np.uint16)
        for w in range(a.shape[1]):  # loop over 64-bit words (4 for ORB, 8 for AKAZE)
            dist += np.bitwise_count(a[:, w, None] ^ b[None, :, w])
        return dist.astype(np.float32)
    a = d_i.astype(np.float32, copy=False)
    b = d_j.astype(np.float32, copy=False)
    # |a|^2 + |b|^2 - 2 a.b, computed in place (the products are the expensive part; the
    # temporaries of a naive expression cost more than the BLAS product at 8k x 8k)
    gram = a @ b.T
    gram *= np.float32(2.0)
    sq = np.add.outer((a * a).sum(1), (b * b).sum(1)).astype(np.float32, copy=False)
    sq -= gram
    del gram
    np.maximum(sq, 0.0, out=sq)
    return sq if squared else np.sqrt(sq, out=sq)


def _two_nearest(dist: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest index, nearest and second-nearest distance along ``axis`` of ``dist``."""
    nn = dist.argmin(axis=axis)
    idx = np.arange(dist.shape[1 - axis])
    where = (idx, nn) if axis == 1 else (nn, idx)
    d1 = dist[where].copy()
    if dist.shape[axis] < 2:
        return nn, d1, np.full_like(d1, np.inf)
    dist[where] = np.inf
    d2 = dist.min(axis=axis)
    dist[where] = d1
    return nn, d1, d2


def mutual_ratio_matches(desc_i: np.ndarray, desc_j: np.ndarray, ratio: float = 0.8):
    """Mutual nearest neighbours that pass Lowe's ratio test in both directions.

    Parameters
    ----------
    desc_i : ndarray, (N_i, D) float32 or uint8
    desc_j : ndarray, (N_j, D), same dtype and ``D``
    ratio : float
        Keep ``(r, s)`` when ``d1 / d2 < ratio`` both for ``r``'s neighbours in ``j`` and for
        ``s``'s neighbours in ``i``.

    Returns
    -------
    pairs : ndarray, (M, 2) int32 — ``(r, s)``, one-to-one by construction
    link_ratio : ndarray, (M,) float32 — the larger of the two directional ratios

    Notes
    -----
    Interpretation: the paper does not say which ratio test it used; taking it in both
    directions makes ``A_ij`` independent of which robot of the pair computes it, so
    ``A_ji = A_ijᵀ`` holds exactly. Exact brute force: one ``(N_i, N_j)`` distance matrix
    (``O(N_i N_j D)``, a BLAS product), L2 for float descriptors and Hamming for binary ones.
    A feature whose only candidate is one descriptor (``N = 1`` on the other side) has no
    second neighbour, so the ratio test cannot reject it: its ratio in that direction is 0
    (the convention of :func:`lowe_ratios` too).
    """
    n_i, n_j = len(desc_i), len(desc_j)
    if n_i == 0 or n_j == 0:
        return np.zeros((0, 2), np.int32), np.zeros(0, np.float32)
    squared = desc_i.dtype != np.uint8
    dist = _distance_matrix(desc_i, desc_j, squared=squared)
    fwd, f1, f2 = _two_nearest(dist, axis=1)  # for each r: best s
    bwd, b1, b2 = _two_nearest(dist, axis=0)  # for each s: best r
    del dist
    if squared:
        f1, f2, b1, b2 = (np.sqrt(v) for v in (f1, f2, b1, b2))
    r = np.arange(n_i)
    mutual = bwd[fwd] == r
    with np.errstate(divide="ignore", invalid="ignore"):
        rf = np.where(np.isinf(f2), 0.0, f1 / f2)
        rb = np.where(np.isinf(b2), 0.0, b1 / b2)
    rf = np.nan_to_num(rf, nan=1.0)  # 0/0: two identical best candidates -> ambiguous
    rb = np.nan_to_num(rb, nan=1.0)
    link_ratio = np.maximum(rf, rb[fwd])
    keep = mutual & (link_ratio < ratio)
    pairs = np.stack([r[keep], fwd[keep]], axis=1).astype(np.int32)
    return pairs, link_ratio[keep].astype(np.float32)


# --------------------------------------------------------------------------- epipolar geometry


def sampson_error_px(F: np.ndarray, x_i: np.ndarray, x_j: np.ndarray) -> np.ndarray:
    """Sampson error of correspondences ``x_i ↔ x_j`` under ``x_jᵀ F x_i = 0``, in pixels.

    Parameters
    ----------
    F : ndarray, (3, 3) — fundamental matrix in pixel coordinates
    x_i, x_j : ndarray, (M, 2) — pixels

    Returns
    -------
    err : ndarray, (M,) float64 — ``sqrt`` of the Sampson distance (Hartley & Zisserman eq. 11.9),
        the first-order approximation of the 2-view reprojection error.
    """
    h_i = np.c_[x_i, np.ones(len(x_i))]
    h_j = np.c_[x_j, np.ones(len(x_j))]
    Fx = h_i @ F.T          # rows F x_i
    Ftx = h_j @ F           # rows F^T x_j
    num = np.einsum("ij,ij->i", h_j, Fx) ** 2
    den = Fx[:, 0] ** 2 + Fx[:, 1] ** 2 + Ftx[:, 0] ** 2 + Ftx[:, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.sqrt(num / den)
    return np.where(den > 0, err, np.inf)


def epipolar_filter(x_i: np.ndarray, x_j: np.ndarray, K_i: np.ndarray | None, K_j: np.ndarray | None,
                    intrinsics_known: bool, threshold_px: float = 1.0, confidence: float = 0.999,
                    max_iters: int = 1000):
    """Epipolar RANSAC (``cv2.USAC_MAGSAC``) on putative correspondences.

    Parameters
    ----------
    x_i, x_j : ndarray, (M, 2) float — pixels, ``M >= 7``
    K_i, K_j : ndarray, (3, 3) or None
    intrinsics_known : bool
        ``True``: essential matrix on points normalised by ``K⁻¹`` (threshold divided by the
        mean focal length); ``False``: fundamental matrix on pixels.
    threshold_px : float
        Inlier threshold in pixels.
    confidence, max_iters : RANSAC stopping rule

    Returns
    -------
    inliers : ndarray, (M,) bool
    F : ndarray, (3, 3) or None — fundamental matrix in pixels (``K_j⁻ᵀ E K_i⁻¹`` for E)
    reason : str — empty on success, else why no model was found

    Notes
    -----
    USAC samples with its own fixed random state (``UsacParams.randomGeneratorState = 0``), so
    the result is repeatable and independent of threads; ``cv2.setRNGSeed`` does not affect it.
    ``cv2.USAC_MAGSAC`` (38), not ``cv2.MAGSAC`` (2 = ``FM_8POINT``).
    """
    m = len(x_i)
    p_i = np.ascontiguousarray(x_i, dtype=np.float64).reshape(-1, 1, 2)
    p_j = np.ascontiguousarray(x_j, dtype=np.float64).reshape(-1, 1, 2)
    try:
        if intrinsics_known:
            Ki_inv, Kj_inv = np.linalg.inv(K_i), np.linalg.inv(K_j)
            f_mean = (K_i[0, 0] + K_i[1, 1] + K_j[0, 0] + K_j[1, 1]) / 4.0
            n_i = cv2.undistortPoints(p_i, K_i, None)
            n_j = cv2.undistortPoints(p_j, K_j, None)
            model, mask = cv2.findEssentialMat(n_i, n_j, np.eye(3), cv2.USAC_MAGSAC,
                                               confidence, threshold_px / f_mean, max_iters)
            if model is not None and model.shape == (3, 3):
                model = Kj_inv.T @ model @ Ki_inv
        else:
            model, mask = cv2.findFundamentalMat(p_i, p_j, cv2.USAC_MAGSAC, threshold_px,
                                                 confidence, max_iters)
    except cv2.error as exc:
        first = str(exc).strip().splitlines()[-1] if str(exc).strip() else "cv2.error"
        return np.zeros(m, bool), None, f"epipolar RANSAC failed ({first})"
    except np.linalg.LinAlgError:
        return np.zeros(m, bool), None, "intrinsics K are singular"
    if model is None or model.shape != (3, 3) or mask is None:
        return np.zeros(m, bool), None, "epipolar RANSAC found no model"
    return mask.reshape(-1).astype(bool), model, ""


# --------------------------------------------------------------------------- one edge, all edges


def lowe_ratios(d_i: np.ndarray, d_j: np.ndarray, pairs: np.ndarray,
                rows_per_block: int = 2048) -> np.ndarray:
    """Lowe ratio of given matches: the distance of ``d_i[r]`` to ``d_j[s]`` over its distance
    to the nearest other descriptor of ``d_j``, ``(M,)`` float32 in ``[0, 1]``.

    For COLMAP's matches (mutual nearest neighbours, so ``s`` is the nearest), which come
    without their ratio. Float descriptors; the products run by blocks of rows.

    A lone candidate (``d_j`` holds one descriptor) has no second neighbour, so the ratio
    test cannot reject it: its ratio is 0, as in :func:`mutual_ratio_matches` (which keeps
    it at any threshold); a second candidate at distance 0 (two identical descriptors) makes
    the match ambiguous, ratio 1, as there too. Every ratio of one match thus means the same
    whichever function computed it.

    The cost is one product ``q dⱼᵀ`` per block; the nearest other descriptor is the one
    that maximises ``q·d − |d|²/2`` (the same order as ``|q − d|²``), found in place on that
    product, and only the two distances of each row are then formed, as
    ``|q|² + |d|² − 2 q·d``: no ``(M, N)`` array of distances is built (on Graffiti's 8470
    matches the ratios are the same bits as from the full distance array, in about half
    its time).
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if len(pairs) == 0 or len(d_j) < 2:  # no second neighbour: nothing to reject the match
        return np.zeros(len(pairs), np.float32)
    out = np.ones(len(pairs), np.float32)
    dj = np.asarray(d_j, dtype=np.float32)
    di = np.asarray(d_i, dtype=np.float32)
    sq_j = (dj * dj).sum(1)
    half_sq_j = np.float32(0.5) * sq_j
    for a in range(0, len(pairs), rows_per_block):
        r, s_ = pairs[a:a + rows_per_block, 0], pairs[a:a + rows_per_block, 1]
        q = di[r]
        dots = q @ dj.T
        rows = np.arange(len(r))
        best_dot = dots[rows, s_].copy()
        dots -= half_sq_j
        dots[rows, s_] = -np.inf
        k = dots.argmax(axis=1)
        sq_q = (q * q).sum(1)
        best = sq_q + sq_j[s_] - 2.0 * best_dot
        second = sq_q + sq_j[k] - 2.0 * (q * dj[k]).sum(1)
        second = np.maximum(second, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.sqrt(np.maximum(best, 0.0)) / np.sqrt(second)
        # another descriptor at distance 0 (a copy of the nearest, or of q): nothing tells the
        # two apart, ratio 1, as mutual_ratio_matches rates two identical best candidates
        ratio = np.where(second > 0, ratio, 1.0)
        out[a:a + len(r)] = np.clip(ratio, 0.0, 1.0)
    return out


#: feature methods whose descriptors COLMAP's matcher takes (SIFT, 128 floats)
COLMAP_MATCHER_FEATURES = ("sift", "colmap-sift")


def check_matcher(matcher: str, features: str) -> None:
    """InputError, before any work, when ``matcher`` cannot take ``features``' descriptors
    (the ``colmap`` matcher takes SIFT only; the check in :func:`_colmap_matches` is the
    same on the descriptors themselves)."""
    if matcher == "colmap" and features not in COLMAP_MATCHER_FEATURES:
        raise InputError(f"--matcher colmap needs SIFT descriptors; --features {features} "
                         f"gives others: use --features colmap-sift or sift, or "
                         f"--matcher opencv")


def _colmap_matches(edges: np.ndarray, features: list[Features], Ks, sizes, known,
                    ratio: float, threshold_px: float | None, min_matches: int,
                    threads: int = -1) -> list[PairMatches]:
    """COLMAP's matching and verification on ``edges`` (:mod:`pipeline.colmap.sift`), as
    PairMatches with the Lowe ratio and Sampson error of each kept match."""
    from pipeline.colmap.sift import match_pairs

    for f in features:
        if f.descriptors.dtype != np.float32 or f.descriptors.shape[1] != 128:
            raise InputError(f"the colmap matcher needs SIFT descriptors (128 floats), got "
                             f"{f.method} {f.descriptors.dtype}x{f.descriptors.shape[1]}; use "
                             f"--features colmap-sift or sift, or --matcher opencv")
    names = [f"image{k}" for k in range(len(features))]
    cams = [(np.asarray(K, np.float64), tuple(int(v) for v in size), bool(kn), bool(kn))
            for K, size, kn in zip(Ks, sizes, known, strict=True)]
    verified = match_pairs(names, [f.keypoints for f in features],
                           [f.descriptors for f in features], cams, edges, threads=threads,
                           ratio=ratio,
                           max_error_px=COLMAP_MAX_ERROR_PX if threshold_px is None
                           else float(threshold_px),
                           min_inliers=max(int(min_matches), COLMAP_MIN_INLIERS))
    out = []
    for v in verified:
        if len(v.pairs) == 0:
            out.append(_empty(v.i, v.j, v.n_putative,
                              f"COLMAP's verification kept no matches ({v.config}, "
                              f"{v.n_putative} putative)"))
            continue
        fi, fj = features[v.i], features[v.j]
        x_i = fi.keypoints[v.pairs[:, 0]].astype(np.float64)
        x_j = fj.keypoints[v.pairs[:, 1]].astype(np.float64)
        F = v.F
        if F is None:  # a planar or panoramic pair: the least-squares F of its inliers
            F, _ = cv2.findFundamentalMat(x_i, x_j, cv2.FM_8POINT) if len(x_i) >= 8 \
                else (None, None)
        err = sampson_error_px(F, x_i, x_j) if F is not None and F.shape == (3, 3) \
            else np.zeros(len(x_i))
        out.append(PairMatches(v.i, v.j, v.pairs.astype(np.int32),
                               lowe_ratios(fi.descriptors, fj.descriptors, v.pairs),
                               err.astype(np.float32), n_putative=v.n_putative, reason=""))
    return out


def _size_of(K: np.ndarray) -> tuple[int, int]:
    """An image size for ``K`` when none is given: twice the principal point."""
    K = np.asarray(K, dtype=np.float64)
    return int(np.ceil(2 * K[0, 2] + 1)), int(np.ceil(2 * K[1, 2] + 1))


def _empty(i: int, j: int, n_putative: int, reason: str) -> PairMatches:
    return PairMatches(i, j, np.zeros((0, 2), np.int32), np.zeros(0, np.float32),
                       np.zeros(0, np.float32), n_putative=n_putative, reason=reason)


def match_pair(i: int, j: int, feats_i: Features, feats_j: Features,
               K_i: np.ndarray | None = None, K_j: np.ndarray | None = None,
               intrinsics_known: bool = True, ratio: float = 0.8, threshold_px: float = 1.0,
               min_matches: int = MIN_MATCHES, confidence: float = 0.999,
               max_iters: int = 1000, matcher: str = "opencv",
               sizes: tuple | None = None) -> PairMatches:
    """The one-to-one association ``A_ij`` of one communication edge (Sec. V-B).

    Parameters
    ----------
    i, j : int
        Camera ids, ``i != j``; if ``i > j`` the result is returned for ``(j, i)``.
    feats_i, feats_j : Features
        Same descriptor kind.
    K_i, K_j : ndarray, (3, 3) or None
        Intrinsics; needed when ``intrinsics_known``.
    intrinsics_known : bool
        Essential matrix (``True``) or fundamental matrix (``False``).
    ratio : float
        Lowe ratio threshold in ``(0, 1]`` (see :func:`mutual_ratio_matches`).
    threshold_px : float or None
        Epipolar inlier threshold in pixels; ``None``: :func:`photo_threshold_px` of the larger
        of the two images (``sizes``), or with the colmap matcher COLMAP's own.
    min_matches : int
        Fewer putative matches or fewer epipolar inliers than this give an empty association
        with ``reason`` set (a 7-point model fits any 7 points, so ``min_matches >= 8``).
    confidence, max_iters : RANSAC settings (see :func:`epipolar_filter`)
    matcher : {"opencv", "colmap"}
        ``colmap``: COLMAP's matching and verification (module notes; ``threshold_px`` is its
        RANSAC ``max_error``, at least :data:`COLMAP_MIN_INLIERS` inliers are asked). The same function for one edge as
        :func:`match_edges` for many, so a robot in its own process matches as the simulator does.
    sizes : ((w_i, h_i), (w_j, h_j)) or None — image sizes, for COLMAP's cameras and a
        ``threshold_px`` of ``None`` (``None``: twice the principal points)

    Returns
    -------
    PairMatches
        ``pairs`` (M, 2) int32 ``(r, s)`` one-to-one, ``ratio`` (M,), ``epipolar_error`` (M,)
        Sampson error in pixels under the RANSAC model, ``n_putative``, ``reason``.

    Raises
    ------
    InputError
        ``i == j``, mixed descriptor kinds, bad ``ratio``/``threshold_px``/``min_matches``, or
        missing/ill-shaped intrinsics when ``intrinsics_known``.
    """
    i, j = int(i), int(j)
    if i == j:
        raise InputError(f"cannot match camera {i} with itself")
    if matcher not in MATCHERS:
        raise InputError(f"matcher {matcher!r}: choose one of {', '.join(MATCHERS)}")
    if i > j:
        i, j, feats_i, feats_j, K_i, K_j = j, i, feats_j, feats_i, K_j, K_i
        sizes = None if sizes is None else (sizes[1], sizes[0])
    if not 0.0 < ratio <= 1.0:
        raise InputError(f"ratio must be in (0, 1], got {ratio}")
    if threshold_px is not None and not threshold_px > 0:
        raise InputError(f"epipolar threshold must be > 0 pixels, got {threshold_px}")
    if min_matches < 8:
        raise InputError(f"min_matches must be >= 8 (a 7-point model fits any 7 matches), got {min_matches}")
    d_i, d_j = feats_i.descriptors, feats_j.descriptors
    if len(feats_i) and len(feats_j) and (d_i.dtype != d_j.dtype or d_i.shape[1] != d_j.shape[1]):
        raise InputError(f"cameras {i} and {j} have different descriptors "
                         f"({feats_i.method} {d_i.dtype}x{d_i.shape[1]} vs "
                         f"{feats_j.method} {d_j.dtype}x{d_j.shape[1]}); extract both with one method")
    if intrinsics_known:
        for cam, K in ((i, K_i), (j, K_j)):
            if K is None or np.shape(K) != (3, 3) or not np.all(np.isfinite(K)):
                raise InputError(f"camera {cam}: intrinsics K must be a finite 3x3 matrix "
                                 f"(got {None if K is None else np.shape(K)}); "
                                 "or pass intrinsics_known=False")
        K_i, K_j = np.asarray(K_i, np.float64), np.asarray(K_j, np.float64)
    if matcher == "colmap":
        if K_i is None or K_j is None:
            raise InputError(f"cameras {i}, {j}: the colmap matcher needs both intrinsics K")
        sizes = sizes or (_size_of(K_i), _size_of(K_j))
        pm = _colmap_matches(np.array([[0, 1]]), [feats_i, feats_j], [K_i, K_j], sizes,
                             [intrinsics_known] * 2, ratio, threshold_px, min_matches, threads=1)[0]
        pm.i, pm.j = i, j
        return pm

    if threshold_px is None:  # scaled with the larger image
        if sizes is None and (K_i is None or K_j is None):
            raise InputError(f"cameras {i}, {j}: an epipolar threshold of None scales with the "
                             "images: give their sizes (or intrinsics K), or a threshold")
        (wi, hi), (wj, hj) = sizes or (_size_of(K_i), _size_of(K_j))
        threshold_px = photo_threshold_px(max(wi, wj), max(hi, hj))
    pairs, link_ratio = mutual_ratio_matches(d_i, d_j, ratio)
    n_put = len(pairs)
    if n_put < min_matches:
        return _empty(i, j, n_put, f"too few putative matches ({n_put} < {min_matches})")
    x_i = feats_i.keypoints[pairs[:, 0]].astype(np.float64)
    x_j = feats_j.keypoints[pairs[:, 1]].astype(np.float64)
    inl, F, why = epipolar_filter(x_i, x_j, K_i, K_j, intrinsics_known, threshold_px,
                                  confidence, max_iters)
    if why:
        return _empty(i, j, n_put, why)
    err = sampson_error_px(F, x_i, x_j)
    n_in = int(inl.sum())
    if n_in < min_matches:
        return _empty(i, j, n_put, f"too few epipolar inliers ({n_in} < {min_matches})")
    return PairMatches(i, j, pairs[inl], link_ratio[inl], err[inl].astype(np.float32),
                       n_putative=n_put, reason="")


#: largest float distance matrix (bytes, float32) for which :func:`match_edges` matches edges on
#: several threads by default: 64 MiB, two 4096-feature images
PARALLEL_MAX_MATRIX_BYTES = 64 * 2**20


def match_edges(features: list[Features], views: list[View], comm_edges, ratio: float = 0.8,
                threshold_px: float | None = 1.0, min_matches: int = MIN_MATCHES,
                confidence: float = 0.999, max_iters: int = 1000,
                workers: int | None = None, matcher: str = "opencv") -> list[PairMatches]:
    """Local associations for every communication edge, and only for those (Sec. II, V-B).

    Parameters
    ----------
    features : list[Features], (n,)
    views : list[View], (n,) — ``K`` and ``intrinsics_known`` of each camera
    comm_edges : array-like, (E, 2) int — undirected communication graph (see
        :func:`pipeline.commgraph.check_comm_edges`); a camera without neighbours simply gets no associations
    ratio, min_matches, confidence, max_iters : see :func:`match_pair`
    threshold_px : float or None
        See :func:`match_pair`; ``None``: :func:`photo_threshold_px` of the larger image of
        each pair.
    workers : int, optional
        Threads over edges. Default ``min(2, cores)``, except for float descriptors whose
        largest distance matrix exceeds :data:`PARALLEL_MAX_MATRIX_BYTES` (one thread: two
        such matrices at once would double the memory). With float descriptors on several
        threads, each product runs on one BLAS thread (``threadpoolctl``): threads over edges
        beat BLAS threads inside each product on the default formation (0.095 s against
        0.137 s for its 15 edges, one machine); binary descriptors' popcount is
        single-threaded and releases the GIL — measured in ``bench/foundation.py``. With
        ``matcher="colmap"``: COLMAP's threads, one by default, for the same matches at every
        call (:func:`pipeline.colmap.sift.match_pairs`).
    matcher : {"opencv", "colmap"}
        ``colmap``: every edge in one call of COLMAP's matcher (its threads; ``threshold_px``
        ``None`` is its own 4 px), the same pairs as :func:`match_pair` edge by edge.

    Returns
    -------
    list[PairMatches], (E,)
        One per edge in input order, each with ``i < j``. Build the links with
        ``Links.from_matches``.

    Raises
    ------
    InputError
        Mismatched lengths of ``features`` and ``views``, a bad edge (unknown camera, self-edge,
        duplicate), or any error of :func:`match_pair`.
    """
    n = len(features)
    if len(views) != n:
        raise InputError(f"{n} feature sets but {len(views)} views; give one of each per camera")
    edges = check_comm_edges(comm_edges, n)
    methods = {f.method for f in features}
    if len(methods) > 1:
        raise InputError(f"cameras use different feature methods {sorted(methods)}; use one")
    if matcher not in MATCHERS:
        raise InputError(f"matcher {matcher!r}: choose one of {', '.join(MATCHERS)}")
    if matcher == "colmap":
        return _colmap_matches(edges, features, [v.K for v in views], [v.size for v in views],
                               [v.intrinsics_known for v in views], ratio, threshold_px,
                               min_matches, threads=workers if workers is not None else 1)

    def one(e):
        i, j = int(e[0]), int(e[1])
        # a fundamental matrix unless both cameras are calibrated
        known = bool(views[i].intrinsics_known and views[j].intrinsics_known)
        return match_pair(i, j, features[i], features[j], views[i].K, views[j].K, known,
                          ratio=ratio, threshold_px=threshold_px, min_matches=min_matches,
                          confidence=confidence, max_iters=max_iters,
                          sizes=(views[i].size, views[j].size))

    from pipeline.progress import progress

    binary = any(f.descriptors.dtype == np.uint8 for f in features)
    if workers is None:
        largest = max((len(features[int(i)]) * len(features[int(j)]) * 4 for i, j in edges),
                      default=0)
        workers = 1 if not binary and largest > PARALLEL_MAX_MATRIX_BYTES \
            else min(2, os.cpu_count() or 1)
    if workers <= 1 or len(edges) <= 1:
        return [one(e) for e in progress(edges, desc="matching pairs")]
    from contextlib import nullcontext

    from threadpoolctl import threadpool_limits

    with (nullcontext() if binary else threadpool_limits(1, user_api="blas")), \
            ThreadPoolExecutor(max_workers=workers) as pool:
        return list(progress(pool.map(one, edges), total=len(edges), desc="matching pairs"))


def step_pairs(robot_of: np.ndarray, step_of: np.ndarray, t: int, window: int,
               edges_up: np.ndarray) -> np.ndarray:
    """Frame pairs ``(a, b)``, ``a < b``, matched at step ``t``: every frame of step ``t``
    against its robot's previous ``window - 1`` frames and the frames of the last ``window``
    steps of the robots it talks to at step ``t`` (``edges_up``).

    Examples
    --------
    >>> step_pairs(np.array([0, 1, 0, 1]), np.array([0, 0, 1, 1]), 1, 2, np.array([[0, 1]])).tolist()
    [[0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    >>> step_pairs(np.array([0, 1, 0, 1]), np.array([0, 0, 1, 1]), 1, 2, np.zeros((0, 2))).tolist()
    [[0, 2], [1, 3]]
    """
    n = int(robot_of.max()) + 1
    talk = np.eye(n, dtype=bool)
    for i, j in np.asarray(edges_up, np.int64).reshape(-1, 2):
        talk[i, j] = talk[j, i] = True
    new = np.flatnonzero(step_of == t)
    win = np.flatnonzero(step_of > t - window)
    out = set()
    for g in new.tolist():
        for h in win.tolist():
            if h != g and talk[robot_of[g], robot_of[h]]:
                out.add((min(g, h), max(g, h)))
    return np.array(sorted(out), np.int64).reshape(-1, 2)
