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

Cost: triangles ``O(deg(r) + deg(s))`` per link; the quadrangle test runs only on links with
no triangle, ``O(Σ_{t ∈ N(r)} deg(t))`` each.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cycle_support"]


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
    L = own.shape[0]
    tau = np.zeros(L, dtype=np.int64)
    quad = np.zeros(L, dtype=bool)
    empty = np.zeros(0, dtype=np.int64)
    for k in range(L):
        r, s = int(own[k]), int(far[k])
        nr = own_lists.get(r, empty)
        ns = lists.get(s, empty)
        cr, cs = camera_of(np.array([r, s]))
        common = np.intersect1d(nr, ns)
        if common.size:
            tau[k] = np.unique(camera_of(common)).size
            continue
        ts = nr[nr != s]
        if ts.size == 0 or ns.size == 0:
            continue
        ct = camera_of(ts)
        ts, ct = ts[(ct != cr) & (ct != cs)], ct[(ct != cr) & (ct != cs)]
        cu_s = camera_of(ns)
        us = ns[(cu_s != cr) & (cu_s != cs)]
        for t, c in zip(ts.tolist(), ct.tolist(), strict=True):
            nt = lists.get(t, empty)
            hit = np.intersect1d(nt, us)
            if hit.size and (camera_of(hit) != c).any():
                quad[k] = True
                break
    return tau, quad
