"""Pair-level loop check: image pairs whose relative rotation breaks the view graph's triangles.

A wrong two-view geometry — two images of repeated structure matched module to module, a
geometrically valid but wrong relation — is *consistent* at the level of features: no two
features of one image meet in one set, so the consistency stage (Aragüés et al., Sec. III)
cannot see it. It breaks the loops of the view graph instead: around a cycle of images the
composed relative rotations of correct pairs give the identity, and a wrong pair makes the
product far from it (Zach, Klopschitz, Pollefeys, "Disambiguating visual relations using loop
constraints", CVPR 2010; Govindu, "Robustness in motion averaging", ACCV 2006).

:func:`loop_check` judges each pair on the triangles ``(i, j, k)`` of the view graph, the
shortest cycles, whose *cycle error* is the angle of ``R_ik⁻¹ R_jk R_ij`` (``R_ab`` the
rotation of camera ``b`` from camera ``a``). The pairs of a database are mostly wrong where a
scene repeats (on the rendered ring of :mod:`data_synth.symmetric`, about half of the pairs
with inliers join two different modules), so a plain majority over all triangles fails: most
triangles of a correct pair hold a wrong pair too. The check therefore follows Enqvist, Kahl
and Olsson ("Non-sequential structure from motion", ICCV Workshops 2011), who build a
cycle-consistent view graph greedily, pairs in decreasing number of inliers:

1. *Greedy pass.* Pairs in decreasing weight (their inlier count; ties by pair); a pair is
   accepted when, among the triangles it closes with pairs accepted before it, the consistent
   ones (cycle error below ``tol_deg``) are at least as many as the inconsistent ones (so a
   pair that closes no triangle yet is accepted).
2. *Vote.* Every accepted pair is judged again on the triangles of the final accepted graph:
   it is kept when it closes at least one consistent triangle and no more inconsistent than
   consistent ones.
3. *Squares.* A kept pair ``(i, j)`` that closes no triangle (two images far apart on the
   ring: no third image is accepted with both) is judged the same way on the cycles
   ``i → k → l → j → i`` of four kept pairs, where an inconsistent square counts against the
   pair only when it is the square's lightest (as in step 1, the weakest pair is blamed; a
   lone inconsistent square drops one pair, not four); a pair on no such cycle either is kept
   (no loop, no verdict).

What this interprets: Enqvist et al. check every cycle a new pair closes, by the spanning tree;
here only cycles of three and four pairs count, because the rotations a database gives are
biased by its focal-length guesses (COLMAP's default is ``1.2 max(w, h)``: 960 px on the
rendered ring, whose truth is 722 px) and the bias grows along a long path, while round a
short cycle of a ring about one axis it largely cancels. Zach et al.'s
inference over cycles is replaced by the three passes above.

Limit: the weights decide whom a failed triangle blames — the pair met later. A wrong pair
heavier than the right pairs of its images is accepted first and the right ones are then
dropped in its place. On the rendered ring the wrong pairs hold 15–30 inliers and the right
ones 100–500; with equal weights the order of the pairs decides.

Centralized: :func:`loop_check` is a pre-pass of ``clean-db`` over all pairs at once (the
greedy pass needs the global order of pairs). A distributed version of step 2 alone needs only
two-hop information: each image sends each neighbour its list of pairs (the other image, the
relative rotation, the weight), ``sum over edges (i, j) of deg(i) + deg(j)`` entries in one
exchange (:attr:`LoopCheck.two_hop_entries`); the greedy order would take further rounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import InputError

__all__ = ["LoopCheck", "loop_check", "cycle_error_deg", "DEFAULT_LOOP_TOL_DEG"]

#: cycle error (degrees) below which a cycle is consistent; on the rendered ring it drops all
#: but 0–7 of the 47–82 wrong pairs and 16–22 of the 69–79 others (bench/images_vs_colmap.py
#: prints what it dropped against the truth)
DEFAULT_LOOP_TOL_DEG = 15.0


@dataclass
class LoopCheck:
    """What :func:`loop_check` decided, per pair (aligned with its ``pairs``).

    Attributes
    ----------
    inconsistent : ndarray, (P,) bool — pairs to drop (they fail their loops)
    consistent_triangles, inconsistent_triangles : ndarray, (P,) int64 — the cycles that
        judged each pair, by verdict: the triangles of the final accepted graph, or the
        squares for a pair on no triangle (step 3); the greedy pass's rejects: the triangles
        it met when rejected
    judged : ndarray, (P,) bool — pairs with a rotation (the others are kept, unjudged)
    two_hop_entries : int — what a one-exchange distributed vote would send (module notes)
    """

    inconsistent: np.ndarray
    consistent_triangles: np.ndarray
    inconsistent_triangles: np.ndarray
    judged: np.ndarray
    two_hop_entries: int

    def summary(self) -> dict:
        """Counts for a report (``pairs_without_triangle``: kept pairs on no cycle at all)."""
        return {"pairs": int(len(self.inconsistent)), "judged": int(self.judged.sum()),
                "pairs_dropped": int(self.inconsistent.sum()),
                "pairs_without_triangle": int((self.judged & ~self.inconsistent
                                               & (self.consistent_triangles
                                                  + self.inconsistent_triangles == 0)).sum()),
                "two_hop_entries": int(self.two_hop_entries)}


def cycle_error_deg(R_ij: np.ndarray, R_jk: np.ndarray, R_ik: np.ndarray) -> np.ndarray:
    """Angle (degrees) of ``R_ikᵀ R_jk R_ij``, the rotation left after going round the
    triangle ``i → j → k → i`` (identity for consistent relative rotations); ``(..., 3, 3)``
    inputs, ``(...)`` output."""
    from scipy.spatial.transform import Rotation

    C = np.swapaxes(R_ik, -1, -2) @ R_jk @ R_ij
    flat = C.reshape(-1, 3, 3)
    return np.degrees(Rotation.from_matrix(flat).magnitude()).reshape(C.shape[:-2])


def _check_inputs(n: int, pairs: np.ndarray, rotations: np.ndarray, weights: np.ndarray,
                  tol_deg: float) -> None:
    if not (np.isfinite(tol_deg) and 0.0 < tol_deg < 180.0):
        raise InputError(f"loop tolerance {tol_deg!r}°: give an angle in degrees between 0 and "
                         f"180 (e.g. {DEFAULT_LOOP_TOL_DEG:g})")
    if pairs.ndim != 2 or pairs.shape[1] != 2:
        raise InputError(f"pairs has shape {pairs.shape}, expected (P, 2)")
    P = len(pairs)
    if rotations.shape != (P, 3, 3) or weights.shape != (P,):
        raise InputError(f"rotations {rotations.shape} / weights {weights.shape} do not match "
                         f"{P} pairs (expected ({P}, 3, 3) / ({P},))")
    if P and ((pairs < 0).any() or (pairs >= n).any() or (pairs[:, 0] >= pairs[:, 1]).any()):
        raise InputError(f"pairs must be (i, j) with 0 <= i < j < {n}")
    key = pairs[:, 0] * n + pairs[:, 1]
    if len(np.unique(key)) != P:
        raise InputError("a pair is listed twice; give each image pair once")


def loop_check(n: int, pairs, rotations, weights, tol_deg: float = DEFAULT_LOOP_TOL_DEG
               ) -> LoopCheck:
    """Which image pairs fail the rotation loops of the view graph (module docstring).

    Parameters
    ----------
    n : number of images
    pairs : (P, 2) int — image pairs ``(i, j)``, ``i < j``, each once
    rotations : (P, 3, 3) float — ``R_ij``, camera ``j``'s rotation from camera ``i``'s
        (``x_j = R_ij x_i + t``); a row of NaN where the pair has none (kept, unjudged)
    weights : (P,) — the pair's confidence, e.g. its inlier count (larger first)
    tol_deg : cycle error below which a triangle is consistent

    Returns
    -------
    LoopCheck

    Raises
    ------
    InputError
        A tolerance outside (0, 180) degrees, or pairs that are not ``i < j < n`` once each.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    rotations = np.asarray(rotations, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    _check_inputs(n, pairs, rotations, weights, float(tol_deg))
    P = len(pairs)
    judged = np.isfinite(rotations).all(axis=(1, 2)) if P else np.zeros(0, dtype=bool)
    index = {(int(a), int(b)): p for p, (a, b) in enumerate(pairs.tolist())}

    def rot(a: int, b: int) -> np.ndarray:
        """``R_ab`` from the stored ``R_min,max``."""
        return rotations[index[(a, b)]] if a < b else rotations[index[(b, a)]].T

    def square_votes(p: int, nbrs: list[set]) -> tuple[int, int]:
        """Cycles ``i → k → l → j → i`` of kept pairs: ``R_ij`` against ``R_lj R_kl R_ik``;
        an inconsistent one counts only where ``p`` is the lightest of its four pairs."""
        i, j = (int(x) for x in pairs[p])
        paths = [(k, ll) for k in sorted(nbrs[i] - {j}) for ll in sorted(nbrs[j] - {i, k})
                 if ll in nbrs[k]]
        if not paths:
            return 0, 0
        R_ik = np.stack([rot(i, k) for k, _ in paths])
        R_kj = np.stack([rot(ll, j) @ rot(k, ll) for k, ll in paths])
        ok = cycle_error_deg(R_ik, R_kj, rotations[p][None]) < tol_deg
        lightest = np.array([rank[p] > max(rank[index[tuple(sorted(e))]]
                                           for e in ((i, k), (k, ll), (ll, j)))
                             for k, ll in paths])
        return int(ok.sum()), int((~ok & lightest).sum())

    def votes(p: int, nbrs: list[set]) -> tuple[int, int]:
        i, j = (int(x) for x in pairs[p])
        ks = sorted(nbrs[i] & nbrs[j])
        if not ks:
            return 0, 0
        R_ij = rotations[p]
        err = cycle_error_deg(R_ij[None], np.stack([rot(j, k) for k in ks]),
                              np.stack([rot(i, k) for k in ks]))
        good = int((err < tol_deg).sum())
        return good, len(ks) - good

    cons = np.zeros(P, dtype=np.int64)
    inc = np.zeros(P, dtype=np.int64)
    accepted = np.zeros(P, dtype=bool)
    nbrs: list[set] = [set() for _ in range(n)]
    # 1. greedy pass, pairs in decreasing weight (Enqvist et al.: a cycle-consistent graph)
    order = np.lexsort((pairs[:, 1], pairs[:, 0], -weights))
    rank = np.empty(P, dtype=np.int64)
    rank[order] = np.arange(P)
    for p in order.tolist():
        if not judged[p]:
            continue
        cons[p], inc[p] = votes(p, nbrs)
        if cons[p] >= inc[p]:
            accepted[p] = True
            i, j = (int(x) for x in pairs[p])
            nbrs[i].add(j)
            nbrs[j].add(i)
    # 2. every accepted pair judged on the triangles of the final accepted graph
    inconsistent = judged & ~accepted
    for p in np.flatnonzero(accepted).tolist():
        cons[p], inc[p] = votes(p, nbrs)
        if cons[p] + inc[p] and (cons[p] == 0 or inc[p] > cons[p]):
            inconsistent[p] = True
    # 3. kept pairs on no triangle: judged on the squares of the kept graph
    kept_nbrs: list[set] = [set() for _ in range(n)]
    for a, b in pairs[accepted & ~inconsistent].tolist():
        kept_nbrs[a].add(b)
        kept_nbrs[b].add(a)
    lonely = np.flatnonzero(accepted & ~inconsistent & (cons + inc == 0)).tolist()
    for p in lonely:
        cons[p], inc[p] = square_votes(p, kept_nbrs)
    for p in lonely:
        if cons[p] + inc[p] and (cons[p] == 0 or inc[p] > cons[p]):
            inconsistent[p] = True
    deg = np.bincount(pairs.ravel(), minlength=n)
    two_hop = int((deg[pairs[:, 0]] + deg[pairs[:, 1]]).sum()) if P else 0
    return LoopCheck(inconsistent=inconsistent, consistent_triangles=cons,
                     inconsistent_triangles=inc, judged=judged, two_hop_entries=two_hop)
