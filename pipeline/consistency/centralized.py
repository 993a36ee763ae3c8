"""Centralized references for the consistency stage — for checking and comparing only.

Nothing here is used by a robot: every function sees the whole association graph.

* :func:`union_find_conflicts` — conflictive sets by connected components (Def. 2.4), the
  ground truth the distributed detection (Sec. III) must reproduce.
* Baselines that real SfM tools apply to the same input, each returning a kept mask ``(L,)``:

  - :func:`drop_conflictive_sets` — OpenMVG / MVE / AliceVision "filter tracks": a track
    holding two features of one image is discarded whole.
  - :func:`keep_first_per_image` — Theia-style track building: in each set, an image keeps
    only its first feature (here: its lowest feature id) and links to the others go.
  - :func:`quality_merge` — a centralized consistent merge (QuickMatch idea): Kruskal over
    the links by decreasing ``Links.quality``, never merging two clusters that share an
    image; an upper reference for how many good links can be kept.
  - :func:`spectral_sync_kept`, :func:`clear_kept` — the multi-way matching baselines of
    :mod:`.spectral` (permutation synchronization, Pachauri et al. 2013; CLEAR-style,
    Fathian et al. 2020), universe size estimated: a link is kept iff both ends get one point.

:data:`BASELINES` names them all; every report lists them on the same input.
"""

from __future__ import annotations

import numpy as np

from pipeline.association import AssociationGraph, camera_offsets, conflictive_labels

__all__ = [
    "union_find_conflicts",
    "drop_conflictive_sets",
    "keep_first_per_image",
    "quality_merge",
    "is_conflict_free",
    "baselines",
    "BASELINES",
    "spectral_sync_kept",
    "clear_kept",
]


def union_find_conflicts(features_per_camera, links, *,
                         graph: AssociationGraph | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Component label and conflict flag of every feature (Def. 2.4), by union-find.

    Parameters
    ----------
    features_per_camera : (n,) int
    links : Links, (L,)
    graph : AssociationGraph or None — the graph of ``links``, when the caller has it

    Returns
    -------
    labels : ndarray, (m_total,) int — connected component (scipy.sparse.csgraph)
    conflictive : ndarray, (m_total,) bool — the feature's set holds two features of one camera
    """
    g = AssociationGraph(features_per_camera, links) if graph is None else graph
    labels, _, conflictive = conflictive_labels(g)
    return labels, conflictive[labels] if labels.size else np.zeros(0, dtype=bool)


def is_conflict_free(features_per_camera, links) -> bool:
    """True when no association set holds two features of one camera."""
    return not union_find_conflicts(features_per_camera, links)[1].any()


def _link_ends(features_per_camera, links) -> tuple[np.ndarray, np.ndarray]:
    off = camera_offsets(features_per_camera)
    return off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j


def drop_conflictive_sets(features_per_camera, links, *, _uf=None) -> np.ndarray:
    """Kept mask ``(L,)``: every link of a conflictive set is dropped ("filter tracks").

    (``_uf``: :func:`union_find_conflicts` of the same input, when the caller has it.)"""
    _, conflictive = union_find_conflicts(features_per_camera, links) if _uf is None else _uf
    a, _ = _link_ends(features_per_camera, links)
    return ~conflictive[a] if len(links) else np.zeros(0, dtype=bool)


def keep_first_per_image(features_per_camera, links, *, _uf=None) -> np.ndarray:
    """Kept mask ``(L,)``: in each set, each image keeps its first (lowest-id) feature only.

    A link is kept when both its features are kept; the surviving links of a set then join
    features of distinct images, so the result is conflict-free.
    """
    fpc = np.diff(camera_offsets(features_per_camera))  # whole counts >= 0, named if not
    labels, _ = union_find_conflicts(fpc, links) if _uf is None else _uf
    if not len(links):
        return np.zeros(0, dtype=bool)
    cam = np.repeat(np.arange(fpc.size), fpc)
    gid = np.arange(labels.size)
    # first feature of each (set, camera): lowest global id, i.e. lowest feature id
    order = np.lexsort((gid, cam, labels))
    key_l, key_c = labels[order], cam[order]
    first = np.r_[True, (key_l[1:] != key_l[:-1]) | (key_c[1:] != key_c[:-1])]
    kept_feature = np.zeros(labels.size, dtype=bool)
    kept_feature[order[first]] = True
    a, b = _link_ends(fpc, links)
    return kept_feature[a] & kept_feature[b]


def quality_merge(features_per_camera, links, *, _uf=None) -> np.ndarray:
    """Kept mask ``(L,)`` of a Kruskal merge by decreasing quality that never joins two
    clusters sharing a camera (QuickMatch idea, centralized).

    A link is kept if it merges two clusters with disjoint cameras, or if its two ends already
    lie in one cluster. Links outside conflictive sets are always kept (their sets already
    hold each camera once), so the loop runs over the links of conflictive sets only. Ties in
    quality are broken by the links' ends, lower camera pair first, then lower features (the
    order of a run's links), so the rows' order of a links file changes nothing.

    Notes
    -----
    ``O(L_c α(L_c))`` union-find operations in Python for the ``L_c`` links of conflictive
    sets; camera sets are Python integers used as bit sets.
    """
    fpc = np.diff(camera_offsets(features_per_camera))  # whole counts >= 0, named if not
    L = len(links)
    kept = np.ones(L, dtype=bool)
    if L == 0:
        return kept
    _, conflictive = union_find_conflicts(fpc, links) if _uf is None else _uf
    a, b = _link_ends(fpc, links)
    todo = np.flatnonzero(conflictive[a])
    if todo.size == 0:
        return kept
    # decreasing quality, ties by the link's ends (camera pair, then features; cam_i < cam_j),
    # not by the row it came in: the same links in another order merge alike
    todo = todo[np.lexsort((links.feat_j[todo], links.feat_i[todo], links.cam_j[todo],
                            links.cam_i[todo], -links.quality[todo]))]
    parent: dict[int, int] = {}
    cams: dict[int, int] = {}

    def find(x: int) -> int:
        root = x
        while parent.get(root, root) != root:
            root = parent[root]
        while parent.get(x, x) != root:  # path compression
            parent[x], x = root, parent[x]
        return root

    ca, cb = links.cam_i.tolist(), links.cam_j.tolist()
    al, bl = a.tolist(), b.tolist()
    for k in todo.tolist():
        ra, rb = find(al[k]), find(bl[k])
        if ra == rb:
            continue
        sa = cams.get(ra, 1 << ca[k])
        sb = cams.get(rb, 1 << cb[k])
        if sa & sb:
            kept[k] = False
            continue
        parent[rb] = ra
        cams[ra] = sa | sb
    return kept


def baselines(features_per_camera, links, *,
              graph: AssociationGraph | None = None) -> dict[str, np.ndarray]:
    """Kept masks ``(L,)`` of every centralized baseline on the same input, by name
    (``graph``: the :class:`AssociationGraph` of ``links``, when the caller has it).

    Returns
    -------
    dict with ``drop_conflictive_sets``, ``keep_first_per_image``, ``quality_merge``, and the
    multi-way matching baselines of :mod:`.spectral`: ``spectral_sync`` (Pachauri et al.
    2013) and ``clear`` (CLEAR-style, Fathian et al. 2020), each with its universe size
    estimated, a link kept iff its two ends get one universe point.
    """
    uf = union_find_conflicts(features_per_camera, links, graph=graph)  # the same sets for all
    return {name: fn(features_per_camera, links, _uf=uf) for name, fn in BASELINES.items()}


def spectral_sync_kept(features_per_camera, links, *, _uf=None) -> np.ndarray:
    """Kept mask of :func:`.spectral.spectral_sync` (universe size estimated)."""
    from pipeline.consistency import spectral

    return spectral.labels_to_kept(features_per_camera, links,
                                   spectral.spectral_sync(features_per_camera, links))


def clear_kept(features_per_camera, links, *, _uf=None) -> np.ndarray:
    """Kept mask of :func:`.spectral.clear_sync` (universe size estimated)."""
    from pipeline.consistency import spectral

    return spectral.labels_to_kept(features_per_camera, links,
                                   spectral.clear_sync(features_per_camera, links))


#: every centralized baseline by name: ``(features_per_camera, links, *, _uf=None) -> kept``
BASELINES = {
    "drop_conflictive_sets": drop_conflictive_sets,
    "keep_first_per_image": keep_first_per_image,
    "quality_merge": quality_merge,
    "spectral_sync": spectral_sync_kept,
    "clear": clear_kept,
}
