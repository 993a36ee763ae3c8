"""The association graph ``G`` and its block adjacency matrix ``W`` (Aragüés et al., Sec. II).

``W`` (eq. 2) has one block ``W_ij`` per camera pair (eq. 3): ``A_ij`` for communication
neighbours, zero otherwise. Feature ``r`` of camera ``i`` has global index ``offsets[i] + r``.

Everything here is *centralized* — it sees the whole graph. It is used to build the robots'
local blocks, to evaluate, and to check the distributed algorithms; never by a robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from pipeline.errors import InputError
from pipeline.types import Links, id_array

__all__ = [
    "AssociationGraph",
    "camera_offsets",
    "check_links",
    "ConflictCounts",
    "count_conflicts",
    "conflictive_links",
    "association_sets",
]


def camera_offsets(features_per_camera) -> np.ndarray:
    """Global index of each camera's first feature, ``(n + 1,)``; last entry is ``m_sum``."""
    if np.ndim(features_per_camera) == 0 and not isinstance(features_per_camera, str):
        # a number of cameras (or of features) given for the list: read as one camera
        raise InputError(f"features_per_camera {features_per_camera!r}: give one count per "
                         "camera (a list or array), not a single number")
    try:
        m = id_array(features_per_camera, "features_per_camera")
    except ValueError as exc:
        raise InputError(f"{exc} (a count of features)") from None
    if (m < 0).any():
        raise InputError(f"features_per_camera must be >= 0, got {m.tolist()}")
    offsets = np.cumsum(m)
    # each count is below 2**63 and every partial sum before it is >= 0, so the first sum an
    # int64 cannot hold wraps to a negative one
    if offsets.size and (offsets < 0).any():
        raise InputError(f"features_per_camera sums to {sum(m.tolist()):,} features, more "
                         f"than an int64 holds ({2**63 - 1:,}); give the counts of the "
                         "features that exist")
    return np.concatenate([[0], offsets])


def check_links(links: Links, features_per_camera) -> None:
    """Raise :class:`InputError` naming the first link that breaks the paper's Assumptions 2.1–2.3.

    Checks: camera and feature ids in range, ``cam_i < cam_j`` (no self-links, each undirected
    link stored once), no duplicate link, and one-to-one per camera pair (Assumption 2.2).
    """
    if not isinstance(links, Links):  # a tuple of columns, None: not an AttributeError below
        raise InputError(f"links must be a pipeline.types.Links (Links(cam_i, feat_i, cam_j, "
                         f"feat_j[, quality])), not {type(links).__name__}")
    m = np.diff(camera_offsets(features_per_camera))  # whole counts >= 0, named if not
    n = len(m)
    L = len(links)
    if L == 0:
        return
    ci, fi, cj, fj = links.cam_i, links.feat_i, links.cam_j, links.feat_j
    bad = np.flatnonzero((ci < 0) | (cj < 0) | (ci >= n) | (cj >= n))
    if bad.size:
        k = bad[0]
        raise InputError(f"link {k} ({ci[k]},{fi[k]})-({cj[k]},{fj[k]}): camera id out of range 0..{n - 1}")
    bad = np.flatnonzero(ci >= cj)
    if bad.size:
        k = bad[0]
        what = "self-link within one camera" if ci[k] == cj[k] else "cam_i must be < cam_j"
        raise InputError(f"link {k} ({ci[k]},{fi[k]})-({cj[k]},{fj[k]}): {what}")
    bad = np.flatnonzero((fi < 0) | (fj < 0) | (fi >= m[ci]) | (fj >= m[cj]))
    if bad.size:
        k = bad[0]
        raise InputError(
            f"link {k} ({ci[k]},{fi[k]})-({cj[k]},{fj[k]}): feature id out of range "
            f"(camera {ci[k]} has {m[ci[k]]} features, camera {cj[k]} has {m[cj[k]]})")
    off = camera_offsets(m)
    a = off[ci] + fi
    b = off[cj] + fj
    for name, key in (("duplicate link", a * off[-1] + b),
                      ("not one-to-one (Assumption 2.2): a feature of camera i is linked twice to camera j", a * n + cj),
                      ("not one-to-one (Assumption 2.2): a feature of camera j is linked twice to camera i", b * n + ci)):
        sk = np.sort(key)
        if not (sk[1:] == sk[:-1]).any():
            continue
        order = np.argsort(key, kind="stable")  # name the first pair
        dup = np.flatnonzero(key[order][1:] == key[order][:-1])
        if dup.size:
            k0, k1 = order[dup[0]], order[dup[0] + 1]
            raise InputError(
                f"links {k0} and {k1} ({ci[k1]},{fi[k1]})-({cj[k1]},{fj[k1]}): {name}")


@dataclass
class AssociationGraph:
    """The association graph ``G`` (Sec. II) in block layout.

    Parameters
    ----------
    features_per_camera : sequence of int, (n,)
    links : Links
        Must satisfy :func:`check_links`.
    """

    features_per_camera: np.ndarray
    links: Links

    def __post_init__(self) -> None:
        # whole counts >= 0, named if not (an int64 cast truncated 2.5 to 2 silently)
        self.offsets = camera_offsets(self.features_per_camera)
        self.features_per_camera = np.diff(self.offsets)
        check_links(self.links, self.features_per_camera)
        self._labels = None  # components(), once computed

    @property
    def n_cameras(self) -> int:
        return int(self.features_per_camera.shape[0])

    @property
    def m_total(self) -> int:
        """Features of all cameras (the paper's ``m_sum`` counts only linked ones, see counts)."""
        return int(self.offsets[-1])

    def global_ids(self) -> tuple[np.ndarray, np.ndarray]:
        """Global feature index of both ends of each link, ``(L,)`` each."""
        return (self.offsets[self.links.cam_i] + self.links.feat_i,
                self.offsets[self.links.cam_j] + self.links.feat_j)

    def adjacency(self) -> sp.csr_matrix:
        """Symmetric boolean ``W`` without the identity blocks (eq. 2–3), ``(m, m)``."""
        a, b = self.global_ids()
        m = self.m_total
        data = np.ones(2 * len(a), dtype=bool)
        return sp.csr_matrix((data, (np.concatenate([a, b]), np.concatenate([b, a]))), shape=(m, m))

    def block(self, i: int, j: int) -> sp.csr_matrix:
        """``W_ij`` as a boolean ``(m_i, m_j)`` sparse matrix; ``W_ii = I`` (Assumption 2.1)."""
        mi, mj = int(self.features_per_camera[i]), int(self.features_per_camera[j])
        if i == j:
            return sp.identity(mi, dtype=bool, format="csr")
        L = self.links
        if i < j:
            sel = (L.cam_i == i) & (L.cam_j == j)
            r, s = L.feat_i[sel], L.feat_j[sel]
        else:
            sel = (L.cam_i == j) & (L.cam_j == i)
            r, s = L.feat_j[sel], L.feat_i[sel]
        return sp.csr_matrix((np.ones(len(r), dtype=bool), (r, s)), shape=(mi, mj))

    def components(self) -> np.ndarray:
        """Connected-component label of every feature, ``(m,)`` (union-find via csgraph;
        computed once per graph, a copy is returned)."""
        if self._labels is None:
            _, self._labels = connected_components(self.adjacency(), directed=False)
        return self._labels.copy()


@dataclass
class ConflictCounts:
    """Paper Table I/III rows for one association graph."""

    links: int
    m_sum: int
    association_sets: int
    conflictive_sets: int
    conflictive_features: int

    def as_dict(self) -> dict:
        return dict(links=self.links, m_sum=self.m_sum, association_sets=self.association_sets,
                    conflictive_sets=self.conflictive_sets,
                    conflictive_features=self.conflictive_features)


def conflictive_labels(graph: AssociationGraph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Component labels, per-component size and per-component conflict flag (Def. 2.4).

    Returns
    -------
    labels : (m,) int — component of every feature
    sizes : (k,) int — features per component
    conflictive : (k,) bool — the component holds two features of one camera
    """
    labels = graph.components()
    k = int(labels.max()) + 1 if labels.size else 0
    sizes = np.bincount(labels, minlength=k)
    cam_of = np.repeat(np.arange(graph.n_cameras), graph.features_per_camera)
    # features per (component, camera); a count >= 2 makes the component conflictive
    per = sp.csr_matrix((np.ones(labels.size, dtype=np.int64), (labels, cam_of)),
                        shape=(k, graph.n_cameras))
    per.sum_duplicates()
    conflictive = np.zeros(k, dtype=bool)
    if per.nnz:
        rows = np.repeat(np.arange(k), np.diff(per.indptr))
        conflictive[rows[per.data >= 2]] = True
    return labels, sizes, conflictive


def conflictive_links(features_per_camera, links: Links) -> np.ndarray:
    """``(L,)`` bool: the links that lie in a conflictive set of their association graph
    (Def. 2.4), e.g. the ledger's ``conflictive_before``."""
    graph = AssociationGraph(features_per_camera, links)
    labels, _, conflictive = conflictive_labels(graph)
    a, _ = graph.global_ids()
    return conflictive[labels[a]] if len(links) else np.zeros(0, dtype=bool)


def count_conflicts(graph: AssociationGraph) -> ConflictCounts:
    """Association sets, conflictive sets, ``m_sum`` and conflictive features (Def. 2.4).

    Association sets are components with at least two features (Def. 2.4 counts lone features
    too; Table III does not: :func:`association_sets`); ``m_sum`` counts the features in them
    (the paper's Table III row "Number of features m_sum").
    """
    labels, sizes, conflictive = conflictive_labels(graph)
    in_set = sizes[labels] >= 2 if labels.size else np.zeros(0, dtype=bool)
    return ConflictCounts(
        links=len(graph.links),
        m_sum=int(in_set.sum()),
        association_sets=int((sizes >= 2).sum()),
        conflictive_sets=int(conflictive.sum()),
        conflictive_features=int(conflictive[labels].sum()) if labels.size else 0,
    )


def association_sets(features_per_camera, links: Links) -> tuple[np.ndarray, list[np.ndarray]]:
    """Association sets of ``links``: connected components with >= 2 features.

    Def. 2.4 calls every connected component of ``G`` an association set, a lone feature
    included. Here, as in :func:`count_conflicts`, a set needs two features: a lone feature is
    associated with nothing, is never conflictive and has no landmark to fuse. The paper's
    Table III fits this reading (formation (a): 528 sets for ``m_sum`` = 1335 associated
    features); its Table I does not say (182 sets for 138 features).

    Sets are numbered in order of their smallest global feature id, so the same links always
    give the same numbering (the triangulation check and the fusion stage rely on it).

    Returns
    -------
    set_of_feature : (m,) int — set id of every feature (global index), -1 for singletons
    sets : list of (k,) int arrays — the global feature ids of each set, ascending
    """
    labels = AssociationGraph(features_per_camera, links).components()
    set_of_feature = np.full(labels.shape, -1, dtype=np.int64)
    if not labels.size:
        return set_of_feature, []
    sizes = np.bincount(labels)
    ids = np.flatnonzero(sizes[labels] >= 2)
    uniq, first = np.unique(labels[ids], return_index=True)
    remap = np.full(int(labels.max()) + 1, -1, dtype=np.int64)
    remap[uniq[np.argsort(first, kind="stable")]] = np.arange(len(uniq))
    set_of_feature[ids] = remap[labels[ids]]
    grouped = ids[np.argsort(set_of_feature[ids], kind="stable")]
    bounds = np.searchsorted(set_of_feature[grouped], np.arange(len(uniq) + 1))
    return set_of_feature, [grouped[bounds[k]:bounds[k + 1]] for k in range(len(uniq))]
