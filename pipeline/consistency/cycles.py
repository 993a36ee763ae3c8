"""Short-cycle support of a link, from what its robot holds after one exchange of link lists.

A good link joins two observations of one landmark; the landmark's other observations close
short cycles over it. A spurious link closes few. Both ends of a link count, from the same
lists, the same cycles:

* ``τ`` — *triangles*: third cameras in which both ends match one common feature (the
  evidence rule's triangle support, :func:`.evidence.triangle_support`);
* ``quad`` — a *quadrangle*: a cycle ``r – t – u – s`` through four different cameras closes
  over the link ``(r, s)``. It matters where the triangles are gone: when a neighbouring pair
  swapped two matches, the good links next to the swap lose their triangles (their third
  camera holds the swapped, wrong matches), while a quadrangle through the cameras beyond
  still closes. A spurious link closes one only by a second coincidence.

What a robot ``i`` holds: its own links (the features ``N(r)`` each own feature ``r`` is
linked to) and, after the support round (:mod:`.sync`), the list ``N(t)`` of every feature
``t`` of a neighbour that is linked to one of its own. For an own link ``(r, s)`` the robot
then knows ``N(r)``, ``N(s)`` and ``N(t)`` for every ``t ∈ N(r)``: enough for both counts.
The far end ``j`` holds ``N(s)``, ``N(r)`` and ``N(u)`` for ``u ∈ N(s)``: the same triangles
and the same quadrangles (``t ∈ N(r)``, ``u ∈ N(s)``, ``t ~ u``), so both ends decide alike.

How much the triangles count (:func:`support_term`)
    A third camera in which both ends match one common feature is evidence for the link; a
    third camera in which both ends are linked but to different features (``shared − τ`` of
    them, ``shared`` the third cameras both ends are linked into) is evidence against it.
    Triangles are not independent evidence where many views see one landmark: a confusion
    between two similar landmarks repeats across the views, and a wrong link then closes
    tens of triangles with other wrong links of the same confusion (CMU hotel, complete graph
    of 101 frames, descriptors only: 5th–95th percentiles of the triangles closed, of 99 third
    cameras, 23–77 for the wrong links between two look-alike corners, 52–95 for their good
    links; counted from the links of ``bench/multiway.py``'s case). So the triangle term counts at
    most :data:`SUPPORT_VIEWS` third cameras at face value and, beyond, the link's agreement
    rate over that many: ``τ · min(1, K / shared)``. On sparse graphs (``shared ≤ K``) it is
    the triangle count itself; on dense ones the agreement rate decides, next to the link's
    own evidence ``λ``. ``K = 3`` keeps the triangle term's range (``3 · TRIANGLE_WEIGHT``,
    6.9) within that of the ratio evidence (``±4.6``), so neither alone overrules the other;
    measured on CMU hotel subsets of 30–101 frames (complete graphs, descriptors only, several
    orders): ``K = 3`` gave the best association on every one, ``K = 4`` or ``5`` lost on the
    50-frame subset (F1 0.992), counting every triangle lost on the 101-frame one (0.994). On
    the ring2 teams and the formations no link has more than ``K`` shared third cameras.

Cost: triangles ``O(deg(r) + deg(s))`` per link; the quadrangle test runs only on links with
no triangle, ``O(Σ_{t ∈ N(r)} deg(t))`` each.
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.keys import isin_sorted, ranges, unique

__all__ = ["cycle_support", "cycle_support_rows", "shared_cameras", "support_term", "SUPPORT_VIEWS"]

#: third cameras whose triangles count at face value (:func:`support_term`)
SUPPORT_VIEWS = 3


def shared_cameras(a: np.ndarray, b: np.ndarray, cam_a: np.ndarray,
                   cam_b: np.ndarray) -> np.ndarray:
    """Third cameras both ends of each link are linked into, among the links given.

    Parameters
    ----------
    a, b : (E,) int — link ends (feature ids), each link once
    cam_a, cam_b : (E,) int — their cameras

    Returns
    -------
    (E,) int64 — ``|cams(N(a)) ∩ cams(N(b))|`` (neither end's own camera is in the other's
    set: no feature links to its own camera)
    """
    E = a.shape[0]
    if E == 0:
        return np.zeros(0, dtype=np.int64)
    nodes, inv = np.unique(np.r_[a, b], return_inverse=True)
    ia, ib = inv[:E], inv[E:]
    cam = np.empty(nodes.size, dtype=np.int64)
    cam[ia], cam[ib] = cam_a, cam_b
    C = np.int64(cam.max()) + 1
    into = unique(np.r_[ia, ib] * C + cam[np.r_[ib, ia]])  # (node, camera it links into)
    ptr = np.searchsorted(into // C, np.arange(nodes.size + 1))
    pos = ranges(ptr[ia], ptr[ia + 1])
    e = np.repeat(np.arange(E), ptr[ia + 1] - ptr[ia])
    hit = isin_sorted(ib[e] * C + into[pos] % C, into)
    return np.bincount(e[hit], minlength=E).astype(np.int64)


def support_term(tau: np.ndarray, shared: np.ndarray, quad: np.ndarray) -> np.ndarray:
    """Cycle support of links in triangle units: ``τ · min(1, K / shared) + q``.

    Parameters
    ----------
    tau : (L,) int — third cameras in which both ends match one common feature
    shared : (L,) int — third cameras both ends are linked into (``≥ τ``)
    quad : (L,) bool — a quadrangle closes over the link (counted only where ``τ = 0``)

    Returns
    -------
    (L,) float64 — ``τ`` for ``shared ≤ K`` (:data:`SUPPORT_VIEWS`), else ``K · τ / shared``
    (the agreement rate over ``K`` views), plus one for a quadrangle without triangle.
    """
    tau = np.asarray(tau, dtype=np.float64)
    shared = np.maximum(np.asarray(shared, dtype=np.float64), 1.0)
    return tau * np.minimum(1.0, SUPPORT_VIEWS / shared) + (np.asarray(quad) & (tau == 0))


def _rows_of(lists: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A dict gid -> list as rows ``(keys ascending, ptr, values)``."""
    if not lists:
        return np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(0, np.int64)
    keys = np.fromiter(lists, dtype=np.int64, count=len(lists))
    order = np.argsort(keys, kind="stable")
    vals = [np.asarray(lists[int(k)], dtype=np.int64).reshape(-1) for k in keys[order]]
    ptr = np.zeros(keys.size + 1, dtype=np.int64)
    np.cumsum([v.size for v in vals], out=ptr[1:])
    return keys[order], ptr, np.concatenate(vals)


def cycle_support(own: np.ndarray, far: np.ndarray, lists: dict[int, np.ndarray],
                  own_lists: dict[int, np.ndarray], camera_of) -> tuple[np.ndarray, np.ndarray]:
    """Triangle count and quadrangle flag of each own link.

    Parameters
    ----------
    own, far : (L,) int64 — global ids of each link's own and far end
    lists : dict gid -> (D,) int64 — ``N(t)`` of the neighbours' features linked to this
        robot (far ends included), as received
    own_lists : dict gid -> (D,) int64 — ``N(r)`` of the robot's own features
    camera_of : callable ``(k,) gids -> (k,) cameras``

    Returns
    -------
    tau : (L,) int64 — third cameras with a common feature of both ends
    quad : (L,) bool — a 4-cycle through four cameras closes over a link with ``tau = 0``
    """
    return cycle_support_rows(own, far, _rows_of(lists), _rows_of(own_lists), camera_of)


#: list entries expanded at once by :func:`cycle_support_rows`
CHUNK = 1 << 22


def cycle_support_rows(own: np.ndarray, far: np.ndarray, rows, own_rows, camera_of,
                       chunk: int = CHUNK) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cycle_support` on lists given as rows: ``rows`` and ``own_rows`` are each
    ``(keys, ptr, values)``, ``keys`` ascending gids, the list of ``keys[x]`` at
    ``values[ptr[x]:ptr[x + 1]]``. Evaluated for every link at once (the lists ``N(t)`` of
    the quadrangle test in pieces of about ``chunk`` entries)."""
    own = np.asarray(own, dtype=np.int64).reshape(-1)
    far = np.asarray(far, dtype=np.int64).reshape(-1)
    L = own.shape[0]
    tau = np.zeros(L, dtype=np.int64)
    quad = np.zeros(L, dtype=bool)
    if L == 0:
        return tau, quad
    K, P, V = (np.asarray(a, dtype=np.int64) for a in rows)
    OK, OP, OV = (np.asarray(a, dtype=np.int64) for a in own_rows)

    def span(keys, ptr, g):
        """``(start, stop)`` of the list of each gid ``g`` (empty where it has none)."""
        if keys.size == 0:
            z = np.zeros(g.shape, dtype=np.int64)
            return z, z
        pos = np.minimum(np.searchsorted(keys, g), keys.size - 1)
        there = keys[pos] == g
        return np.where(there, ptr[pos], 0), np.where(there, ptr[pos + 1], 0)

    def cams(g):
        return np.asarray(camera_of(g), dtype=np.int64).reshape(-1)

    ids = unique(np.concatenate([OV, V]))  # every listed gid, as a dense index
    W = np.int64(max(ids.size, 1))

    def index(g):
        return np.searchsorted(ids, g)

    cr, cs = cams(own), cams(far)
    # N(r) of each link, as (link, t)
    a0, a1 = span(OK, OP, own)
    e_r = np.repeat(np.arange(L, dtype=np.int64), a1 - a0)
    nr = OV[ranges(a0, a1)]
    # N(s) of each link, as sorted keys link * W + index
    b0, b1 = span(K, P, far)
    e_s = np.repeat(np.arange(L, dtype=np.int64), b1 - b0)
    ns = V[ranges(b0, b1)]
    ns_keys = np.sort(e_s * W + index(ns))
    # τ: cameras of the features in both lists
    hit = isin_sorted(e_r * W + index(nr), ns_keys)
    if hit.any():
        cam_common = cams(nr[hit])
        C = np.int64(max(int(cam_common.max()), int(cr.max()), int(cs.max())) + 1)
        pairs = unique(e_r[hit] * C + cam_common)
        tau = np.bincount(pairs // C, minlength=L).astype(np.int64)
    # quadrangles, on links without a triangle: t in N(r) \ {s}, u in N(s), both on cameras
    # other than r's and s's, t ~ u on two different cameras
    ct_all = cams(nr) if nr.size else np.zeros(0, np.int64)
    keep = (tau[e_r] == 0) & (nr != far[e_r]) & (ct_all != cr[e_r]) & (ct_all != cs[e_r])
    e_t, ts, ct = e_r[keep], nr[keep], ct_all[keep]
    cu = cams(ns) if ns.size else np.zeros(0, np.int64)
    ok_u = (cu != cr[e_s]) & (cu != cs[e_s])
    us_keys = np.sort(e_s[ok_u] * W + index(ns[ok_u]))
    if ts.size == 0 or us_keys.size == 0:
        return tau, quad
    c0, c1 = span(K, P, ts)
    done = np.cumsum(c1 - c0)
    start = 0
    while start < ts.size:
        before = int(done[start - 1]) if start else 0
        stop = max(start + 1, int(np.searchsorted(done, before + chunk, side="right")))
        sl = slice(start, stop)
        n_u = c1[sl] - c0[sl]
        u = V[ranges(c0[sl], c1[sl])]
        k = np.repeat(e_t[sl], n_u)
        found = isin_sorted(k * W + index(u), us_keys) & (cams(u) != np.repeat(ct[sl], n_u))
        quad[k[found]] = True
        start = stop
    return tau, quad
