"""Evaluation of an association against the ground truth of a rendered formation.

The rows "good links", "spurious links" and "missing links" of the paper's Table I
(Aragüés et al., Sec. V-A: true positives, false positives and false negatives of the local
associations) for the synthetic formations, where the truth is known from depth:

- a *good link* joins two keypoints that image the same surface point (docs/DESIGN.md: the 3D point
  of one reprojects within ``tol_px`` of the other, visible in both — depth test);
- a *spurious link* is any other link;
- a *missing link* is a true pair between detected keypoints on a communication edge that the
  association does not contain.

The geometry lives in :mod:`data_synth.ground_truth`; this module only groups links per camera
pair and counts. Centralized: it sees every camera, so it is used to judge the robots, never by
them.
"""

from __future__ import annotations

import numpy as np

from pipeline.commgraph import check_comm_edges
from pipeline.errors import InputError
from pipeline.types import Features, Links

__all__ = ["link_truth", "missing_links", "missing_links_per_edge", "MissingLinks", "link_counts"]


def _check(formation, features: list[Features], links: Links) -> None:
    n = len(formation.views)
    if len(features) != n:
        raise InputError(f"{len(features)} feature sets for a formation of {n} cameras")
    if len(links) and (links.cam_i.min() < 0 or links.cam_j.max() >= n):
        raise InputError(f"links name cameras outside 0..{n - 1}")
    m = np.array([len(f) for f in features], dtype=np.int64)
    if len(links) and ((links.feat_i < 0).any() or (links.feat_j < 0).any()
                       or (links.feat_i >= m[links.cam_i]).any()
                       or (links.feat_j >= m[links.cam_j]).any()):
        raise InputError("links name features that the given Features do not have")


def link_truth(formation, features: list[Features], links: Links, tol_px: float = 2.0) -> np.ndarray:
    """Which links are good (Table I "good links"), ``(L,)`` bool.

    Parameters
    ----------
    formation : data_synth Formation
        Rendered views with depth and poses.
    features : list[Features], (n,)
    links : Links, (L,)
    tol_px : float
        Reprojection tolerance in pixels.

    Returns
    -------
    good : ndarray, (L,) bool — ``~good`` are the spurious links

    Notes
    -----
    One call of :func:`data_synth.ground_truth.good_links` per camera pair present in
    ``links`` (vectorized over that pair's links).
    """
    from data_synth.ground_truth import good_links

    _check(formation, features, links)
    good = np.zeros(len(links), dtype=bool)
    if not len(links):
        return good
    n = len(features)
    key = links.cam_i * n + links.cam_j
    for k in np.unique(key):
        sel = np.flatnonzero(key == k)
        i, j = int(k // n), int(k % n)
        good[sel] = np.asarray(good_links(formation, i, features[i].keypoints[links.feat_i[sel]],
                                          j, features[j].keypoints[links.feat_j[sel]],
                                          tol_px=tol_px), dtype=bool).reshape(-1)
    return good


def missing_links_per_edge(formation, features: list[Features], links: Links, comm_edges,
                           tol_px: float = 2.0) -> np.ndarray:
    """Missing links of each communication edge (Table I "missing links"), ``(E,)`` int64.

    A missing link of edge ``(i, j)`` is a true pair ``(r, s)`` between detected keypoints of
    ``i`` and ``j`` (one-to-one, from :func:`data_synth.ground_truth.true_pairs`) that
    ``links`` does not contain. Pairs of cameras that do not communicate are never counted:
    matching is not allowed to find them (Sec. II).

    Parameters
    ----------
    formation, features, links, tol_px : see :func:`link_truth`
    comm_edges : array-like, (E, 2) int — validated with
        :func:`pipeline.commgraph.check_comm_edges`

    Returns
    -------
    missing : ndarray, (E,) int64, in the order of ``comm_edges``
    """
    _check(formation, features, links)
    return MissingLinks(formation, features, comm_edges, tol_px).per_edge(links)


class MissingLinks:
    """:func:`missing_links_per_edge` of many link sets on one formation's features: the true
    pairs of every communication edge are looked up once, each link set then costs one
    vectorized membership test.

    Parameters
    ----------
    formation, features, comm_edges, tol_px : see :func:`missing_links_per_edge`
    """

    def __init__(self, formation, features: list[Features], comm_edges, tol_px: float = 2.0):
        from data_synth.ground_truth import true_pairs

        self.n = len(features)
        self.m = np.array([len(f) for f in features], dtype=np.int64)
        self._features = features
        self._formation = formation
        edges = check_comm_edges(comm_edges, self.n)
        self.n_edges = len(edges)
        self._base = int(max(self.m.max(initial=0), 1))
        keys, edge_of = [], []
        for e, (i, j) in enumerate(edges.tolist()):
            if not self.m[i] or not self.m[j]:
                continue
            truth = np.asarray(true_pairs(formation, i, features[i].keypoints, j,
                                          features[j].keypoints, tol_px=tol_px),
                               dtype=np.int64).reshape(-1, 2)
            keys.append(self._key(i, j, truth[:, 0], truth[:, 1]))
            edge_of.append(np.full(len(truth), e, dtype=np.int64))
        self._truth = np.concatenate(keys) if keys else np.zeros(0, np.int64)
        self._edge = np.concatenate(edge_of) if edge_of else np.zeros(0, np.int64)

    def _key(self, i, j, r, s) -> np.ndarray:
        """One integer per (camera i, camera j, feature r of i, feature s of j)."""
        return ((np.asarray(i, np.int64) * self.n + j) * self._base + r) * self._base + s

    def per_edge(self, links: Links) -> np.ndarray:
        """Missing links of each communication edge, ``(E,)`` int64."""
        _check(self._formation, self._features, links)
        found = self._key(links.cam_i, links.cam_j, links.feat_i, links.feat_j)
        missing = ~np.isin(self._truth, found)
        return np.bincount(self._edge[missing], minlength=self.n_edges).astype(np.int64)

    def __call__(self, links: Links) -> int:
        """Total missing links of ``links`` over all communication edges."""
        return int(self.per_edge(links).sum())


def missing_links(formation, features: list[Features], links: Links, comm_edges,
                  tol_px: float = 2.0) -> int:
    """Total missing links over all communication edges (see :func:`missing_links_per_edge`)."""
    return int(missing_links_per_edge(formation, features, links, comm_edges, tol_px).sum())


def link_counts(formation, features: list[Features], links: Links, comm_edges,
                tol_px: float = 2.0) -> dict:
    """Good, spurious and missing links and the raw precision, as one dict.

    Returns
    -------
    dict
        ``good_links``, ``spurious_links``, ``missing_links`` (int) and ``precision``
        (good / all links, ``nan`` without links).
    """
    good = link_truth(formation, features, links, tol_px)
    n_good = int(good.sum())
    return {"good_links": n_good, "spurious_links": int(len(good) - n_good),
            "missing_links": missing_links(formation, features, links, comm_edges, tol_px),
            "precision": n_good / len(good) if len(good) else float("nan")}
