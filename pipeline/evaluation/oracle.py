"""The resolution oracle and the scores that judge a resolution against the truth (synthetic).

Centralized and truth-aware: it sees every link and knows which are good, so it is used to
judge the robots' resolution (Aragüés et al., Sec. IV), never by them.

* :func:`oracle_cut` — the best a resolution could do on the input's conflictive sets: cut
  every spurious link there, then the fewest good links that leave no conflict (Def. 2.4).
  The second step is a minimum multicut (every two features of one camera separated), solved
  exactly as an integer program by constraint generation: minimise the number of cut links
  subject to "every path between two features of one camera has a cut link", adding the
  shortest still-uncut path of each conflicting pair until the kept graph is conflict-free
  (``scipy.optimize.milp``, HiGHS).
* :func:`resolution_scores` — good cut, spurious cut, spurious links inside the input's
  conflictive sets and those left there, for any kept mask.

Only links inside conflictive sets are ever cut (outside them nothing is in conflict), so the
oracle's good cuts are the unavoidable ones: conflicts among good links only, typically two
keypoints of one image a fraction of a pixel apart that both image the point within the truth
tolerance.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from pipeline.association import camera_offsets
from pipeline.consistency.centralized import union_find_conflicts
from pipeline.errors import InputError
from pipeline.types import Links, id_array

__all__ = ["oracle_cut", "min_conflict_cut", "resolution_scores",
           "links_in_conflictive_sets"]


def _ends(features_per_camera, links: Links) -> tuple[np.ndarray, np.ndarray]:
    off = camera_offsets(features_per_camera)
    return off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j


def _conflict_paths(n_nodes: int, cam: np.ndarray, a: np.ndarray, b: np.ndarray,
                    kept: np.ndarray) -> list[np.ndarray]:
    """For every component of the kept graph with two features of one camera, one shortest
    kept path (as link indices) between such a pair per camera and extra feature."""
    idx = np.flatnonzero(kept)
    g = sp.csr_matrix((np.ones(idx.size), (a[idx], b[idx])), shape=(n_nodes, n_nodes))
    g = (g + g.T).tocsr()
    _, label = connected_components(g, directed=False)
    key = label.astype(np.int64) * (int(cam.max(initial=0)) + 1) + cam
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.r_[True, ks[1:] != ks[:-1]]
    head = order[np.maximum.accumulate(np.where(first, np.arange(ks.size), 0))]
    pairs = [(int(h), int(o)) for h, o, f in zip(head, order, first, strict=True) if not f]
    if not pairs:
        return []
    edge_of = {}
    for k in idx.tolist():
        edge_of[(int(a[k]), int(b[k]))] = k
        edge_of[(int(b[k]), int(a[k]))] = k
    paths, trees = [], {}
    for src, dst in pairs:
        if src not in trees:
            trees[src] = breadth_first_order(g, src, directed=False, return_predecessors=True)[1]
        pred = trees[src]
        path, v = [], dst
        while v != src:
            u = int(pred[v])
            path.append(edge_of[(u, v)])
            v = u
        paths.append(np.array(path, dtype=np.int64))
    return paths


def min_conflict_cut(cam: np.ndarray, a: np.ndarray, b: np.ndarray,
                     max_rounds: int = 200) -> np.ndarray:
    """Fewest links whose cut leaves no two features of one camera connected (exact).

    Parameters
    ----------
    cam : ndarray, (V,) int — camera of each node (nodes ``0..V-1``)
    a, b : ndarray, (E,) int — link ends
    max_rounds : int — constraint-generation rounds before giving up

    Returns
    -------
    cut : ndarray, (E,) bool

    Raises
    ------
    InputError
        ``cam``, ``a`` or ``b`` not whole numbers, ``a`` and ``b`` of other lengths, or an
        end outside ``0..V-1``.
    RuntimeError
        The integer program did not converge within ``max_rounds`` rounds.

    Notes
    -----
    Minimum multicut as an integer program over ``z_e ∈ {0, 1}`` (1 = cut), with one
    constraint ``Σ_{e ∈ P} z_e ≥ 1`` per generated path ``P`` between two features of one
    camera; paths are added until the solution is feasible for *all* paths, so the result is
    optimal. Exponential in the worst case; conflictive sets are small.
    """
    cam, a, b = _nodes(cam, a, b)
    E = int(a.size)
    cut = np.zeros(E, dtype=bool)
    if E == 0:
        return cut
    rows: list[np.ndarray] = []
    for _ in range(max_rounds):
        paths = _conflict_paths(int(cam.size), cam, a, b, ~cut)
        if not paths:
            return cut
        # SciPy's optimizers load only when a conflict needs solving (0.05 s, 10 MiB)
        from scipy.optimize import Bounds, LinearConstraint, milp

        rows.extend(paths)
        A = sp.csr_matrix((np.ones(sum(p.size for p in rows)),
                           (np.repeat(np.arange(len(rows)), [p.size for p in rows]),
                            np.concatenate(rows))), shape=(len(rows), E))
        res = milp(np.ones(E), constraints=LinearConstraint(A, lb=1, ub=np.inf),
                   integrality=np.ones(E), bounds=Bounds(0, 1))
        if res.x is None:
            raise RuntimeError(f"oracle integer program failed: {res.message}")
        cut = res.x > 0.5
    raise RuntimeError(f"oracle cut did not converge in {max_rounds} rounds")


def _nodes(cam, a, b) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``cam``, ``a``, ``b`` of :func:`min_conflict_cut` as int64 arrays; InputError naming
    what is wrong (lists failed with AttributeError, an end past the nodes with an IndexError
    deep in the path search)."""
    try:
        cam, a, b = (id_array(v, name) for v, name in ((cam, "cam"), (a, "a"), (b, "b")))
    except ValueError as exc:
        raise InputError(f"min_conflict_cut: {exc}") from None
    if a.size != b.size:
        raise InputError(f"min_conflict_cut: a has {a.size} link ends and b {b.size}; give "
                         "one entry per link in each")
    bad = np.flatnonzero((a < 0) | (a >= cam.size) | (b < 0) | (b >= cam.size))
    if bad.size:
        k = int(bad[0])
        raise InputError(f"min_conflict_cut: link {k} ({int(a[k])}, {int(b[k])}) names a node "
                         f"outside 0..{cam.size - 1}, the nodes of cam")
    return cam, a, b


def _per_link(mask, n_links: int, name: str) -> np.ndarray:
    """``mask`` as an ``(L,)`` bool array; InputError when it has another shape (numpy would
    broadcast a single entry over every link, or fail with a broadcasting message)."""
    v = np.asarray(mask)
    if v.shape != (n_links,):
        raise InputError(f"{name} has shape {v.shape}; give one entry per link ({n_links},)")
    if v.dtype != bool:
        # a cast would read -1 (the ledger's 'unknown' truth), 0.4 or 'no' as True
        bad = np.flatnonzero(~np.isin(v, [0, 1])) if v.dtype.kind in "iuf" else \
            np.arange(min(1, v.size))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"{name}[{k}] = {v[k].item()!r}: give booleans (or 0 / 1), one per "
                             "link" + (" (LinkLedger.truth holds -1 for an unknown link: "
                                       "pass ledger.good)" if name == "truth" else ""))
    return v.astype(bool)


def oracle_cut(features_per_camera, links: Links, truth: np.ndarray, *, graph=None) -> np.ndarray:
    """Kept mask ``(L,)`` of the oracle: spurious links of conflictive sets cut, then the
    fewest good links there that leave the graph conflict-free.

    Parameters
    ----------
    features_per_camera : (n,) int
    links : Links, (L,)
    truth : ndarray, (L,) bool — good links
    graph : AssociationGraph or None — the graph of ``links``, when the caller has it

    Returns
    -------
    kept : ndarray, (L,) bool
    """
    # counts as camera_offsets checks them: a cast to int64 read 2.5 features as 2
    fpc = np.diff(camera_offsets(features_per_camera))
    truth = _per_link(truth, len(links), "truth")
    kept = np.ones(len(links), dtype=bool)
    if not len(links):
        return kept
    _, conflictive = union_find_conflicts(fpc, links, graph=graph)
    a, b = _ends(fpc, links)
    in_sets = conflictive[a]
    kept[in_sets & ~truth] = False
    rest = np.flatnonzero(in_sets & truth)
    if rest.size == 0:
        return kept
    nodes, inv = np.unique(np.r_[a[rest], b[rest]], return_inverse=True)
    cam = np.searchsorted(camera_offsets(fpc), nodes, side="right") - 1
    cut = min_conflict_cut(cam, inv[:rest.size], inv[rest.size:])
    kept[rest[cut]] = False
    return kept


def resolution_scores(features_per_camera, links: Links, truth: np.ndarray,
                      kept: np.ndarray, *, in_sets: np.ndarray | None = None) -> dict:
    """Good cut, spurious cut, spurious in the input's conflictive sets, spurious left there.

    Parameters
    ----------
    features_per_camera : (n,) int
    links : Links, (L,) — the input of the resolution
    truth : ndarray, (L,) bool — good links
    kept : ndarray, (L,) bool — what the resolution kept
    in_sets : ndarray, (L,) bool or None — which links lie in the input's conflictive sets
        (:func:`links_in_conflictive_sets`), when the caller scores several masks of one input

    Returns
    -------
    dict with ``good_cut``, ``spurious_cut``, ``spurious_in_sets``, ``spurious_left``,
    ``links_in_sets`` (int)
    """
    truth = _per_link(truth, len(links), "truth")
    kept = _per_link(kept, len(links), "kept")
    if in_sets is None:
        in_sets = links_in_conflictive_sets(features_per_camera, links)
    else:  # a list failed on .sum(), another length with numpy's broadcasting message
        in_sets = _per_link(in_sets, len(links), "in_sets")
    return {"good_cut": int((~kept & truth).sum()), "spurious_cut": int((~kept & ~truth).sum()),
            "spurious_in_sets": int((in_sets & ~truth).sum()),
            "spurious_left": int((in_sets & ~truth & kept).sum()),
            "links_in_sets": int(in_sets.sum())}


def links_in_conflictive_sets(features_per_camera, links: Links, *, graph=None) -> np.ndarray:
    """Which links lie in a conflictive set of ``links`` (Def. 2.4), ``(L,)`` bool
    (``graph``: the :class:`~pipeline.association.AssociationGraph` of ``links``, if built)."""
    if not len(links):
        return np.zeros(0, dtype=bool)
    _, conflictive = union_find_conflicts(features_per_camera, links, graph=graph)
    return conflictive[_ends(features_per_camera, links)[0]]
