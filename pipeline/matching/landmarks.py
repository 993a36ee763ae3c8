"""One-to-one matching of labelled landmarks between communication neighbours.

Each robot matches its landmarks to each neighbour's by the Hungarian algorithm on the
descriptor distances (``scipy.optimize.linear_sum_assignment``): χ² for histograms (shape
contexts), L2 for vectors (SIFT). That is the pairwise input multi-view matching methods
such as CLEAR (Fathian et al., T-RO 2020) take on the CMU hotel benchmark.

An assignment covers every landmark of the smaller side even where the descriptors say
nothing; a *distance gate* in the form of Lowe's ratio test keeps an assigned pair only if
its distance is at most ``ratio`` times the best alternative either robot had — the
nearest other landmark in its row or its column (Lowe, IJCV 2004; default 0.8, the value
the rest of the pipeline uses for its mutual ratio test). ``ratio=None`` keeps the whole
assignment (the ungated input).

*Guided matching* (Hartley & Zisserman, *Multiple View Geometry*, Sec. 11.6 / 4.8): the
robot fits a fundamental matrix to the assignment by RANSAC (``cv2.USAC_MAGSAC``,
:func:`pipeline.matching.pairs.epipolar_filter`), then
solves the assignment again with every pair whose Sampson error exceeds the threshold
forbidden. The labelled keypoints' own positions thus settle pairs whose descriptors are
ambiguous (two nearby landmarks with similar shape contexts). Where no model is found
(fewer than 8 assigned pairs, or RANSAC fails) the descriptor assignment is kept. It is
kept too when a homography explains the assignment almost as well as the fundamental
matrix — more than ``MAX_H_INLIER_RATIO`` = 0.8 of the F inliers are H inliers, COLMAP's
default test for a degenerate (planar or short-baseline) two-view geometry — because F is
then poorly constrained and its band would cut true pairs.

Threshold (stated): 3 px. Hand-labelled landmarks are integer pixel positions clicked by a
person, far coarser than the sub-pixel keypoints the image pipeline checks at 1 px; 3 px is
the 3σ band of a 1 px labelling error. Measured on the CMU hotel: at 1 px the epipolar
models of near frames (short baselines) reject true pairs and the ring / knn runs lose
recall (``bench/landmarks_clear.py``, README); at 3 px they do not.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["chi2_distance", "l2_distance", "hungarian_match", "guided_match",
           "match_landmark_edges", "GEOMETRY", "EPIPOLAR_PX"]

GEOMETRY = ("epipolar", "none")
#: inlier threshold of the epipolar check for hand-labelled keypoints, pixels (module notes)
EPIPOLAR_PX = 3.0
_FORBIDDEN = 1e12
#: elements of one block of :func:`chi2_distance`'s temporaries (8 MB each, five alive at once)
_CHI2_BLOCK = 2 ** 20
#: landmark pairs of one block of :func:`guided_match`'s epipolar band (about 40 MB)
_PAIRS_BLOCK = 2 ** 18
#: COLMAP's ``TwoViewGeometryOptions.max_H_inlier_ratio``: above it F is degenerate
MAX_H_INLIER_RATIO = 0.8


def chi2_distance(h_i: np.ndarray, h_j: np.ndarray) -> np.ndarray:
    """χ² distance of histograms, ``(K_i, K_j)``.

    ``χ²(a, b) = ½ Σ_k (a_k − b_k)² / (a_k + b_k)`` on histograms normalised to sum 1 (bins
    empty in both count 0), as for shape contexts (Belongie et al., PAMI 2002). In ``[0, 1]``.

    Parameters
    ----------
    h_i : (K_i, B) non-negative
    h_j : (K_j, B) non-negative
    """
    a = _normalise(np.asarray(h_i, dtype=np.float64))
    b = _normalise(np.asarray(h_j, dtype=np.float64))
    if a.shape[1] != b.shape[1]:
        raise InputError(f"histograms with {a.shape[1]} and {b.shape[1]} bins cannot be compared")
    out = np.empty((a.shape[0], b.shape[0]))
    # a block of rows at a time: the (rows, K_j, B) temporaries of all rows at once took
    # 7.8 GB for 2000 landmarks of 60 bins
    step = max(1, _CHI2_BLOCK // max(1, b.shape[0] * a.shape[1]))
    for r in range(0, a.shape[0], step):
        ab = a[r:r + step, None, :]
        s = ab + b[None, :, :]
        d = (ab - b[None, :, :]) ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.where(s > 0, d / s, 0.0)
        out[r:r + step] = 0.5 * q.sum(axis=2)
    return out


def _normalise(h: np.ndarray) -> np.ndarray:
    tot = h.sum(axis=1, keepdims=True)
    return np.divide(h, tot, out=np.zeros_like(h), where=tot > 0)


def l2_distance(d_i: np.ndarray, d_j: np.ndarray) -> np.ndarray:
    """Euclidean distance of descriptor vectors, ``(K_i, K_j)``."""
    a = np.asarray(d_i, dtype=np.float64)
    b = np.asarray(d_j, dtype=np.float64)
    sq = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
    return np.sqrt(np.maximum(sq, 0.0))


def hungarian_match(cost: np.ndarray, ratio: float | None = 0.8
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-cost one-to-one assignment, then the ratio gate (module notes).

    Parameters
    ----------
    cost : (K_i, K_j) float — descriptor distances
    ratio : float in (0, 1] or None — gate; ``None`` keeps every assigned pair

    Returns
    -------
    pairs : (M, 2) int64 — rows ``(r, s)``
    distance : (M,) float64 — ``cost[r, s]``
    ratio_of_pair : (M,) float64 — ``cost[r, s]`` over the nearest alternative in row ``r``
        or column ``s``; 0 when there is none (a single landmark on each side: no
        alternative, so the gate cannot reject the pair; the convention of
        :func:`pipeline.matching.pairs.lowe_ratios`)

    Examples
    --------
    >>> c = np.array([[0.1, 0.9], [0.8, 0.2]])
    >>> hungarian_match(c)[0].tolist()
    [[0, 0], [1, 1]]
    """
    cost = np.asarray(cost, dtype=np.float64)
    if cost.ndim != 2:
        raise InputError(f"cost matrix must be 2-D, got shape {cost.shape}")
    if cost.size == 0:
        z = np.zeros(0)
        return np.zeros((0, 2), dtype=np.int64), z, z
    r, s = linear_sum_assignment(cost)
    d = cost[r, s]
    masked = cost.copy()
    masked[r, s] = np.inf
    alt = np.minimum(masked[r].min(axis=1), masked[:, s].min(axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(alt > 0, d / alt, np.where(d > 0, np.inf, 1.0))
    keep = np.ones(r.size, dtype=bool) if ratio is None else rho <= ratio
    return np.stack([r[keep], s[keep]], axis=1).astype(np.int64), d[keep], rho[keep]


def guided_match(cost: np.ndarray, x_i: np.ndarray, x_j: np.ndarray,
                 threshold_px: float = EPIPOLAR_PX) -> tuple[np.ndarray, bool]:
    """Assignment, epipolar RANSAC on it, assignment again within the epipolar band.

    Parameters
    ----------
    cost : (K_i, K_j) float — descriptor distances
    x_i : (K_i, 2), x_j : (K_j, 2) — keypoints, pixels
    threshold_px : float — Sampson error bound

    Returns
    -------
    pairs : (M, 2) int64 — rows ``(r, s)``
    model_found : bool — ``False``: no usable fundamental matrix (none found, or degenerate:
        a homography explains the assignment as well), ``pairs`` is the plain assignment
    """
    import cv2

    from pipeline.matching.pairs import epipolar_filter, sampson_error_px

    cost = np.asarray(cost, dtype=np.float64)
    r, s = linear_sum_assignment(cost)
    if r.size < 8:
        return np.stack([r, s], axis=1).astype(np.int64), False
    a, b, swap = _canonical_pairs(x_i[r], x_j[s], x_i, x_j)
    inl, F, _ = epipolar_filter(a, b, None, None, False, threshold_px)
    if F is None:
        return np.stack([r, s], axis=1).astype(np.int64), False
    F = F.T if swap else F
    try:
        H, h_mask = cv2.findHomography(a, b, cv2.USAC_MAGSAC, threshold_px)
    except cv2.error:
        H, h_mask = None, None
    if H is not None and h_mask is not None and \
            int(h_mask.sum()) > MAX_H_INLIER_RATIO * int(inl.sum()):
        return np.stack([r, s], axis=1).astype(np.int64), False
    ki, kj = cost.shape
    err = np.empty((ki, kj))
    # a block of rows at a time: the pairs of all rows at once took 4.3 GB for 5000 landmarks
    step = max(1, _PAIRS_BLOCK // max(1, kj))
    for r in range(0, ki, step):
        rows = x_i[r:r + step]
        err[r:r + step] = sampson_error_px(F, np.repeat(rows, kj, axis=0),
                                           np.tile(x_j, (len(rows), 1))).reshape(-1, kj)
    band = np.where(err <= threshold_px, cost, _FORBIDDEN)
    r, s = linear_sum_assignment(band)
    ok = band[r, s] < _FORBIDDEN
    return np.stack([r[ok], s[ok]], axis=1).astype(np.int64), True


def _canonical_pairs(p_i: np.ndarray, p_j: np.ndarray, x_i: np.ndarray, x_j: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, bool]:
    """The assigned pairs ``(p_i[t], p_j[t])`` as RANSAC is to see them: the two images in an
    order fixed by their keypoints (``swap``: ``x_j``'s first), the pairs sorted by position.

    RANSAC draws its samples by index (USAC's fixed random state), so the model it returns
    depends on the order of its input; in this order it depends on the labelled positions
    only, not on the order of the landmarks in the label files nor on which of the two images
    comes first by name.
    """
    def key(x: np.ndarray) -> tuple:
        return (len(x), *map(tuple, x[np.lexsort(x.T[::-1])].tolist()))

    swap = key(x_j) < key(x_i)
    a, b = (p_j, p_i) if swap else (p_i, p_j)
    order = np.lexsort((b[:, 1], b[:, 0], a[:, 1], a[:, 0]))
    return (np.ascontiguousarray(a[order], dtype=np.float64),
            np.ascontiguousarray(b[order], dtype=np.float64), swap)


def _ratio_of(cost: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Distance of each pair over the nearest alternative in its row or column."""
    if not len(pairs):
        return np.zeros(0)
    r, s = pairs[:, 0], pairs[:, 1]
    masked = np.asarray(cost, dtype=np.float64).copy()
    d = masked[r, s].copy()
    masked[r, s] = np.inf
    alt = np.minimum(masked[r].min(axis=1), masked[:, s].min(axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(alt > 0, d / alt, np.where(d > 0, np.inf, 1.0))


def match_landmark_edges(descriptors: list[np.ndarray], comm_edges: np.ndarray,
                         kind: str = "histogram", ratio: float | None = 0.8,
                         keypoints: list[np.ndarray] | None = None,
                         geometry: str = "none", epipolar_px: float = EPIPOLAR_PX
                         ) -> tuple[Links, dict]:
    """Links of every communication edge ``(i, j)``: Hungarian on the descriptor distance.

    Each edge is matched once, as robot ``i`` would after receiving ``j``'s descriptors.

    Parameters
    ----------
    descriptors : list of (K_i, D) arrays, one per robot
    comm_edges : (E, 2) int, ``i < j``
    kind : ``histogram`` (χ²) or ``vector`` (L2)
    ratio : gate of :func:`hungarian_match` (on the final pairs)
    keypoints : list of (K_i, 2) or None — needed for ``geometry="epipolar"``
    geometry : ``none`` (descriptors only) or ``epipolar`` (:func:`guided_match`)
    epipolar_px : float — Sampson error bound of the epipolar check

    Returns
    -------
    links : Links — quality ``1 − ratio_of_pair`` (higher is better, as for the image pipeline)
    stats : dict — ``edges``, ``edges_without_model`` (epipolar: plain assignment kept)
    """
    if kind not in ("histogram", "vector"):
        raise InputError(f"descriptor kind {kind!r}: expected histogram or vector")
    if ratio is not None and not 0 < ratio <= 1:
        raise InputError(f"--ratio {ratio}: expected a value in (0, 1], or none")
    if geometry not in GEOMETRY:
        raise InputError(f"--geometry {geometry!r}: expected one of {', '.join(GEOMETRY)}")
    if geometry == "epipolar" and keypoints is None:
        raise InputError("--geometry epipolar needs the keypoints of every image")
    if not 0 < epipolar_px < float("inf"):
        raise InputError(f"--epipolar-px {epipolar_px}: expected a positive, finite number of "
                         "pixels")
    dist = chi2_distance if kind == "histogram" else l2_distance
    ci, fi, cj, fj, q = [], [], [], [], []
    edges = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
    no_model = 0
    for i, j in edges.tolist():
        cost = dist(descriptors[i], descriptors[j])
        if geometry == "epipolar":
            pairs, found = guided_match(cost, np.asarray(keypoints[i], dtype=np.float64),
                                        np.asarray(keypoints[j], dtype=np.float64), epipolar_px)
            no_model += not found
            rho = _ratio_of(cost, pairs)
            if ratio is not None:
                pairs, rho = pairs[rho <= ratio], rho[rho <= ratio]
        else:
            pairs, _, rho = hungarian_match(cost, ratio)
        ci.append(np.full(len(pairs), i))
        cj.append(np.full(len(pairs), j))
        fi.append(pairs[:, 0])
        fj.append(pairs[:, 1])
        q.append(1.0 - rho)
    stats = {"edges": int(len(edges)), "geometry": geometry,
             "edges_without_model": int(no_model)}
    if geometry == "epipolar":
        stats["epipolar_px"] = float(epipolar_px)
    if not ci:
        z = np.zeros(0, dtype=np.int64)
        return Links(z, z, z, z, np.zeros(0)), stats
    return Links(np.concatenate(ci), np.concatenate(fi), np.concatenate(cj), np.concatenate(fj),
                 np.concatenate(q)), stats
