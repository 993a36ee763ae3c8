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
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["chi2_distance", "l2_distance", "hungarian_match", "match_landmark_edges"]


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
    s = a[:, None, :] + b[None, :, :]
    d = (a[:, None, :] - b[None, :, :]) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(s > 0, d / s, 0.0)
    return 0.5 * q.sum(axis=2)


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
        or column ``s`` (``inf`` when there is none, e.g. a single landmark)

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


def match_landmark_edges(descriptors: list[np.ndarray], comm_edges: np.ndarray,
                         kind: str = "histogram", ratio: float | None = 0.8) -> Links:
    """Links of every communication edge ``(i, j)``: Hungarian on the descriptor distance.

    Each edge is matched once, as robot ``i`` would after receiving ``j``'s descriptors.

    Parameters
    ----------
    descriptors : list of (K_i, D) arrays, one per robot
    comm_edges : (E, 2) int, ``i < j``
    kind : ``histogram`` (χ²) or ``vector`` (L2)
    ratio : gate of :func:`hungarian_match`

    Returns
    -------
    Links — quality ``1 − ratio_of_pair`` (higher is better, as for the image pipeline)
    """
    if kind not in ("histogram", "vector"):
        raise InputError(f"descriptor kind {kind!r}: expected histogram or vector")
    if ratio is not None and not 0 < ratio <= 1:
        raise InputError(f"--ratio {ratio}: expected a value in (0, 1], or none")
    dist = chi2_distance if kind == "histogram" else l2_distance
    ci, fi, cj, fj, q = [], [], [], [], []
    for i, j in np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2).tolist():
        pairs, _, rho = hungarian_match(dist(descriptors[i], descriptors[j]), ratio)
        ci.append(np.full(len(pairs), i))
        cj.append(np.full(len(pairs), j))
        fi.append(pairs[:, 0])
        fj.append(pairs[:, 1])
        q.append(1.0 - rho)
    if not ci:
        z = np.zeros(0, dtype=np.int64)
        return Links(z, z, z, z, np.zeros(0))
    return Links(np.concatenate(ci), np.concatenate(fi), np.concatenate(cj), np.concatenate(fj),
                 np.concatenate(q))
