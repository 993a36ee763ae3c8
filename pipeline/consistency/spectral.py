"""Centralized multi-way matching baselines: permutation synchronization and a CLEAR-style method.

Both turn the pairwise links of all cameras into one cycle-consistent association: every
feature gets the *universe point* (label) it images, or ``-1`` when it is left unassigned, and
no two features of one camera share a label. Two features are associated iff they share a
label ``>= 0``; :func:`labels_to_kept` says which input links such an answer keeps. Pure
functions of the whole association graph, for comparison only (never used by a robot).

Notation (both papers). ``m`` features in all, ``n`` cameras, camera ``i`` with ``m_i``
features at global ids ``offset[i] + r`` (``offset`` = cumulative ``features_per_camera``).
The *association matrix* ``W`` (``m x m``, symmetric) has the blocks ``W_ij`` = the links
between cameras ``i`` and ``j`` (0/1, or the link weights) and ``W_ii = I``. A consistent
association into ``k`` universe points is ``W = X X^T`` with ``X`` (``m x k``) 0/1, each
camera's rows a partial permutation (Pachauri et al. 2013, with full permutations; Fathian et
al. 2020, the "lifting" ``X`` to the universe).

* :func:`spectral_sync` — Pachauri, Kondor, Singh, "Solving the multi-way matching problem by
  permutation synchronization", NIPS 2013. The top-``k`` eigenvectors ``U`` of ``W`` span the
  column space of ``X`` when the links are consistent (``W = X X^T``, so ``W U = U Λ``); each
  image's block ``U_i`` is then rounded to a (partial) permutation by the Hungarian method
  against a reference. Pachauri et al. (Alg. 1) take image 1 as the reference
  (``sigma_i = argmax_sigma <U_i U_1^T, sigma>`` by Kuhn–Munkres), which needs every point
  seen by image 1; here every point is seen by *some*
  feature, so the reference is ``k`` representative features found by column-pivoted QR of the
  row-normalised ``U^T`` (Damle, Minden, Ying, "Simple, direct and efficient multi-way spectral
  clustering", Inf. Inference 2019, Alg. 1) — the ``k`` most linearly independent rows.
* :func:`clear_sync` — a CLEAR-style method: Fathian, Khosoussi, Tian, Lusk, How, "CLEAR: A
  consistent lifting, embedding, and alignment rectification algorithm for multiview data
  association", IEEE T-RO 2020 (Alg. 1): the normalized Laplacian of the association graph,
  the universe size from its spectrum, its kernel as the spectral embedding, pivot rows as
  cluster centres and a per-image assignment to them.

Eigenvectors, one connected component of the association graph at a time (its spectrum is
the union of theirs; :class:`_Spectrum`): dense (``scipy.linalg.eigh``) for a component of
at most :data:`DENSE_MAX` features, else ARPACK Lanczos on the sparse matrix
(``scipy.sparse.linalg.eigsh``, fixed random start vector: deterministic). Memory is
``O(L + m k)`` while the leading eigenpairs suffice (complete graphs: CMU hotel, 3030
features, about 25 MB traced). A universe-size estimate that needs more eigenvalues than a
first window (sparse graphs, where a point seen along a chain of cameras has many small
Laplacian eigenvalues) solves a component of at most :data:`DENSE_VALUES_MAX` features
densely: ``O(m_c^2)`` memory, ``O(m_c^3)`` time.

Features without any link are left out of the eigenproblem and unassigned (``-1``): their row
of ``W`` is a unit vector, an eigenvector of eigenvalue 1 that carries no information and is
degenerate with every other such feature's (any rotation among them is an equally valid
eigenbasis, so they would be clustered together at random).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from scipy.optimize import linear_sum_assignment
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import eigsh

from pipeline.association import camera_offsets
from pipeline.errors import InputError
from pipeline.types import Links

__all__ = [
    "spectral_sync",
    "clear_sync",
    "labels_to_kept",
    "association_matrix",
    "universe_size_gap",
    "universe_size_count",
    "DENSE_MAX",
    "DENSE_VALUES_MAX",
    "ARPACK_MAX_K",
    "CLEAR_THRESHOLD",
    "MAJORITY",
    "ZERO_EIG",
]

#: most features solved with a dense eigendecomposition (a 500 x 500 float64 matrix is 2 MB)
DENSE_MAX = 500
#: largest connected component whose whole spectrum is computed densely (values only) when a
#: universe-size estimate needs more eigenvalues than a first ARPACK window gives (4000: a
#: 128 MB matrix)
DENSE_VALUES_MAX = 4000
#: most eigenpairs asked of ARPACK for a matrix that could be solved densely (measured on a
#: 2323-feature ring2 component: 124 eigenpairs by ARPACK took as long as all by ``eigh``)
ARPACK_MAX_K = 64
#: CLEAR's universe size: eigenvalues of the normalized Laplacian below this are counted.
#: For a consistent association on a complete graph the spectrum is exactly {0, 1} (0 once per
#: universe point, 1 for the rest, see :func:`universe_size_count`): 0.5 is the midpoint.
CLEAR_THRESHOLD = 0.5
#: eigenvalues of the normalized Laplacian below this are round-off zeros
ZERO_EIG = 1e-9
#: spectral_sync keeps a feature's assignment only when more than half of its embedding's
#: energy lies along the universe point it is assigned to: cosine > 1 / sqrt(2)
MAJORITY = 1.0 / np.sqrt(2.0)
#: a row of the embedding shorter than this times the longest row carries no direction
_ZERO_ROW = 1e-8
#: relative difference below which two pivot scores are a tie (broken by the lowest id): far
#: above the rounding of eigenvectors (~1e-12 here), far below the gaps that decide
_TIE = 1e-7
_SEED = 0


# ------------------------------------------------------------------------------ input


def _offsets(features_per_camera) -> np.ndarray:
    return camera_offsets(features_per_camera)  # whole counts >= 0, named if not


def _link_ends(features_per_camera, links: Links) -> tuple[np.ndarray, np.ndarray]:
    """Global ids ``(a, b)`` of both ends of every link; InputError naming the first link
    with an end out of range (matches as given: many-to-many links are this input)."""
    off = _offsets(features_per_camera)
    n = off.size - 1
    fpc = np.diff(off)
    ci, fi, cj, fj = links.cam_i, links.feat_i, links.cam_j, links.feat_j
    bad = np.flatnonzero((ci < 0) | (cj < 0) | (ci >= n) | (cj >= n))
    if bad.size:
        k = bad[0]
        raise InputError(f"link {k} ({ci[k]},{fi[k]})-({cj[k]},{fj[k]}): camera id out of "
                         f"range 0..{n - 1}")
    bad = np.flatnonzero((fi < 0) | (fj < 0) | (fi >= fpc[ci]) | (fj >= fpc[cj]))
    if bad.size:
        k = bad[0]
        raise InputError(f"link {k} ({ci[k]},{fi[k]})-({cj[k]},{fj[k]}): feature id out of "
                         f"range (camera {ci[k]} has {fpc[ci[k]]} features, camera {cj[k]} "
                         f"has {fpc[cj[k]]})")
    return off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j


def association_matrix(features_per_camera, links: Links,
                       weight: np.ndarray | None = None) -> sp.csr_matrix:
    """The symmetric association matrix ``W = A + I`` (``m x m``, CSR, float64).

    ``A`` holds every link between two cameras in both directions with its weight (1 when
    ``weight`` is None); a pair listed twice counts once, with its larger weight. A link
    inside one camera is ignored: ``W_ii = I`` (the distinctness constraint, Fathian et al.
    2020; Pachauri et al. 2013 likewise set the diagonal blocks to the identity).

    Parameters
    ----------
    features_per_camera : (n,) int
    links : Links, (L,)
    weight : (L,) float >= 0, or None

    Examples
    --------
    >>> W = association_matrix([1, 1], Links([0], [0], [1], [0]))
    >>> W.toarray().tolist()
    [[1.0, 1.0], [1.0, 1.0]]
    """
    a, b = _link_ends(features_per_camera, links)
    m = int(_offsets(features_per_camera)[-1])
    w = np.ones(len(a)) if weight is None else np.asarray(weight, dtype=np.float64).reshape(-1)
    if w.shape[0] != len(a):
        raise ValueError(f"weight has length {w.shape[0]}, expected {len(a)} (one per link)")
    if not np.isfinite(w).all() or (w < 0).any():
        raise ValueError("link weights must be finite and non-negative")
    keep = (links.cam_i != links.cam_j) & (w > 0)
    a, b, w = a[keep], b[keep], w[keep]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * max(m, 1) + hi
    order = np.argsort(key, kind="stable")
    key, w = key[order], w[order]
    first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if key.size else key
    w = np.maximum.reduceat(w, first) if key.size else w
    lo, hi = key[first] // max(m, 1), key[first] % max(m, 1)
    rows = np.concatenate([lo, hi, np.arange(m)])
    cols = np.concatenate([hi, lo, np.arange(m)])
    vals = np.concatenate([w, w, np.ones(m)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(m, m))


@dataclass
class _Problem:
    """The linked features: their global ids, cameras, ``W`` restricted to them, and the
    connected components of their association graph."""

    m_total: int
    active: np.ndarray       # (m,) global ids of features with at least one link
    camera: np.ndarray       # (m,) camera of each
    W: sp.csr_matrix         # (m, m)
    k_min: int               # most linked features of one camera: the universe is at least this
    comp: np.ndarray         # (m,) connected component of each
    members: list[np.ndarray]  # per component, its rows (sorted)
    k_min_comp: np.ndarray   # (components,) most features of one camera in the component


def _problem(features_per_camera, links, weight) -> _Problem:
    W = association_matrix(features_per_camera, links, weight)
    off = _offsets(features_per_camera)
    degree = np.diff(W.indptr) - 1          # off-diagonal entries per row
    active = np.flatnonzero(degree > 0)
    n_cam = off.size - 1
    camera = np.repeat(np.arange(n_cam), np.diff(off))[active]
    k_min = int(np.bincount(camera).max()) if active.size else 0
    W = W[active][:, active].tocsr()
    n_comp, comp = connected_components(W, directed=False)
    size = np.bincount(comp, minlength=n_comp)
    members = np.split(np.argsort(comp, kind="stable"), np.cumsum(size)[:-1])
    keys, counts = np.unique(comp.astype(np.int64) * max(n_cam, 1) + camera, return_counts=True)
    k_min_comp = np.zeros(n_comp, dtype=np.int64)
    np.maximum.at(k_min_comp, keys // max(n_cam, 1), counts)
    return _Problem(int(off[-1]), active, camera, W, k_min, comp, members, k_min_comp)


def _normalized(W: sp.csr_matrix) -> sp.csr_matrix:
    """``D^-1/2 W D^-1/2``, ``D = diag(W 1)`` (degree counting the identity)."""
    d = 1.0 / np.sqrt(np.asarray(W.sum(axis=1)).ravel())
    Dh = sp.diags(d)
    return (Dh @ W @ Dh).tocsr()


# -------------------------------------------------------------------------- spectrum


def _top_eigen(M: sp.csr_matrix, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` largest eigenvalues (descending) of symmetric ``M`` and their eigenvectors:
    dense ``eigh`` for a small matrix, for ``k`` a quarter of ``m`` or more, or for ``k`` above
    :data:`ARPACK_MAX_K` when ``m`` is at most :data:`DENSE_VALUES_MAX` (Lanczos then costs
    more than the dense solver); else ARPACK."""
    m = M.shape[0]
    k = min(k, m)
    if k <= 0:
        return np.zeros(0), np.zeros((m, 0))
    if m <= DENSE_MAX or 4 * k >= m or (k > ARPACK_MAX_K and m <= DENSE_VALUES_MAX):
        vals, vecs = scipy.linalg.eigh(M.toarray(), subset_by_index=[m - k, m - 1],
                                       driver="evr")
    else:
        v0 = np.random.default_rng(_SEED).standard_normal(m)
        vals, vecs = eigsh(M, k=k, which="LA", v0=v0, ncv=min(m, max(2 * k + 1, 20)))
    order = np.argsort(-vals, kind="stable")
    return vals[order], vecs[:, order]


class _Spectrum:
    """Leading eigenpairs of a symmetric non-negative matrix, one connected component at a
    time (as CLEAR's block SVD does), computed lazily.

    Why by component: the spectrum of a block-diagonal matrix is the union of its blocks',
    each eigenvector lives on one block; and Lanczos (ARPACK) started from one vector finds a
    repeated eigenvalue once, while a consistent association made of ``c`` identical
    components (clean data) repeats every eigenvalue ``c`` times. Components of at most
    :data:`DENSE_MAX` features are solved densely, batched by size. A larger one starts with
    the leading eigenpairs asked for (:func:`_top_eigen`); when more eigenvalues are needed,
    all of them are computed densely (with their eigenvectors when ``keep_vectors``, else
    values only) if it has at most :data:`DENSE_VALUES_MAX` features, else the ARPACK window
    doubles. Other eigenvectors are computed only for the eigenvalues finally used.
    """

    def __init__(self, M: sp.csr_matrix, prob: _Problem, keep_vectors: bool = True):
        self.M = M
        self.keep_vectors = keep_vectors
        self.members = prob.members
        self.size = np.array([mem.size for mem in prob.members], dtype=np.int64)
        n_comp = self.size.size
        self.vals: list[np.ndarray] = [np.zeros(0)] * n_comp       # descending
        self.vecs: list[np.ndarray] = [np.zeros((0, 0))] * n_comp  # leading columns
        self.large = np.flatnonzero(self.size > DENSE_MAX).tolist()
        self._dense_small(prob.comp)

    def _dense_small(self, comp: np.ndarray) -> None:
        local = np.empty(comp.size, dtype=np.int64)
        for mem in self.members:
            local[mem] = np.arange(mem.size)
        coo = self.M.tocoo()
        for s in np.unique(self.size[self.size <= DENSE_MAX]).tolist():
            same = np.flatnonzero(self.size == s)
            step = max(1, 4_000_000 // (s * s))           # at most 32 MB of blocks at once
            for lo in range(0, same.size, step):
                cs = same[lo:lo + step]
                slot = np.full(self.size.size, -1)
                slot[cs] = np.arange(cs.size)
                on = slot[comp[coo.row]] >= 0
                r, c = coo.row[on], coo.col[on]
                blocks = np.zeros((cs.size, s, s))
                blocks[slot[comp[r]], local[r], local[c]] = coo.data[on]
                w, v = np.linalg.eigh(blocks)                 # ascending
                for t, ci in enumerate(cs.tolist()):
                    self.vals[ci] = w[t, ::-1].copy()
                    self.vecs[ci] = v[t][:, ::-1].copy()

    def _sub(self, c: int) -> sp.csr_matrix:
        mem = self.members[c]
        return self.M[mem][:, mem].tocsr()

    def _values(self, c: int, count: int) -> None:
        """At least ``count`` leading eigenvalues of large component ``c``."""
        size = int(self.size[c])
        count = min(count, size)
        if self.vals[c].size >= count:
            return
        if self.vals[c].size and size <= DENSE_VALUES_MAX:
            if self.keep_vectors:     # all pairs at once: one dense solve instead of two
                w, v = scipy.linalg.eigh(self._sub(c).toarray(), driver="evd")
                self.vals[c], self.vecs[c] = w[::-1].copy(), v[:, ::-1].copy()
            else:
                self.vals[c] = scipy.linalg.eigvalsh(self._sub(c).toarray())[::-1].copy()
        else:
            if self.vals[c].size:
                count = max(count, min(size, 2 * self.vals[c].size))
            self.vals[c], self.vecs[c] = _top_eigen(self._sub(c), count)

    def top_counts(self, k: int) -> np.ndarray:
        """How many of the ``k`` largest eigenvalues of the whole matrix lie in each component
        (ties: lower component first)."""
        for c in self.large:
            if not self.vals[c].size:
                self._values(c, k)
        while True:
            pool = np.concatenate(self.vals)
            tau = -np.inf if pool.size <= k else np.partition(pool, pool.size - k)[pool.size - k]
            grow = [c for c in self.large
                    if self.vals[c].size < self.size[c] and self.vals[c][-1] >= tau]
            if not grow:
                break
            for c in grow:
                self._values(c, 2 * self.vals[c].size)
        comp = np.concatenate([np.full(v.size, c) for c, v in enumerate(self.vals)])
        idx = np.concatenate([np.arange(v.size) for v in self.vals])
        pick = np.lexsort((idx, comp, -np.concatenate(self.vals)))[:k]
        return np.bincount(comp[pick], minlength=self.size.size)

    def down_to(self, level: float, k_start: np.ndarray) -> list[np.ndarray]:
        """Per component, its eigenvalues above ``level`` and the largest one at or below it
        (all of them if none is), descending. ``k_start``: first window per component."""
        for c in self.large:
            self._values(c, int(k_start[c]))
            while self.vals[c].size < self.size[c] and self.vals[c][-1] > level:
                self._values(c, 2 * self.vals[c].size)
        out = []
        for v in self.vals:
            cut = np.flatnonzero(v <= level)
            out.append(v[:cut[0] + 1] if cut.size else v)
        return out

    def vectors(self, c: int, count: int) -> np.ndarray:
        """The ``count`` leading eigenvectors of component ``c``, ``(size, count)``."""
        if self.vecs[c].shape[1] < count:
            vals, self.vecs[c] = _top_eigen(self._sub(c), count)
            if self.vals[c].size < vals.size:
                self.vals[c] = vals
        return self.vecs[c][:, :count]


def universe_size_count(mu: np.ndarray, k_min: int,
                        threshold: float = CLEAR_THRESHOLD) -> int:
    """CLEAR's universe size: the eigenvalues of the normalized Laplacian
    ``L_nrm = I - D^-1/2 W D^-1/2`` below ``threshold``, at least ``k_min``.

    ``mu`` are eigenvalues of ``N = D^-1/2 W D^-1/2`` (``L_nrm = I - N``), so the count is that
    of ``mu > 1 - threshold``. Why ``{0, 1}``: a consistent association on a complete graph is
    ``W = X X^T``; a universe point seen by ``s`` features is an all-ones ``s x s`` block of
    ``N`` divided by ``s``, with eigenvalues 1 (once) and 0 — so ``L_nrm`` has one 0 per
    universe point and 1 elsewhere (Fathian et al. 2020, the kernel of the normalized
    Laplacian has the dimension of the universe). ``k_min`` = the most features of one camera
    (they are distinct points, so the universe is at least that large; CLEAR's code bounds the
    estimate the same way).

    Examples
    --------
    >>> universe_size_count(np.array([1.0, 0.98, 0.9, 0.3, 0.1]), k_min=2)
    3
    """
    return max(int(k_min), int((np.asarray(mu) > 1.0 - threshold).sum()))


def universe_size_gap(mu: np.ndarray, k_min: int) -> int:
    """Universe size by the largest eigengap of the normalized Laplacian, measured as a ratio:
    ``argmax_k lambda_{k+1} / lambda_k`` over ``k >= k_min`` (1-based), ``lambda = 1 - mu``
    ascending, ``mu`` the leading eigenvalues of ``N = D^-1/2 W D^-1/2`` (descending) down to
    the first at or below 0.5 (so ``lambda_k < 0.5`` for every candidate but the last).

    Why normalized: with partial visibility a point seen by ``s`` cameras has eigenvalue about
    ``s`` in ``W``, so ``W``'s largest gap falls between often and rarely seen points;
    normalized, every consistent point has ``lambda = 0`` whatever its ``s``
    (:func:`universe_size_count`). Why a ratio: wrong and missing links lift a point's 0 by an
    amount that follows the noise, and a point seen along a sparse graph (a long chain of
    cameras) has further small eigenvalues that shrink with its length; an absolute gap
    ``lambda_{k+1} - lambda_k`` then prefers the wide spacings far from 0 (on a clean chain
    of 20 cameras, the gap after the 4th mode of each chain), a ratio is scale-free and
    finds where the spectrum leaves the near-kernel. Values below :data:`ZERO_EIG` = 1e-9 are
    round-off (exact zeros are solved to about 1e-14) and count as 1e-9, so a run of them has
    ratio 1. Ties go to the smaller ``k``; ``k_min`` when ``mu`` offers no candidate.

    Examples
    --------
    >>> universe_size_gap(np.array([1.0, 0.97, 0.95, 0.2]), k_min=2)   # lambda 0, .03, .05, .8
    3
    >>> universe_size_gap(np.array([1.0, 0.3]), k_min=1)   # one camera each: one point
    1
    """
    mu = np.asarray(mu, dtype=np.float64)
    if mu.size < 2 or k_min >= mu.size:
        return int(k_min)
    lam = np.maximum(1.0 - mu, ZERO_EIG)
    ratio = lam[1:] / lam[:-1]                # ratio[k - 1] = lambda_{k+1} / lambda_k
    lo = max(int(k_min), 1)
    return lo + int(np.argmax(ratio[lo - 1:]))


def _unit_rows(U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``U`` scaled to length 1, and which rows have a direction at all."""
    norm = np.linalg.norm(U, axis=1)
    ok = norm > _ZERO_ROW * (norm.max() if norm.size else 0.0)
    Un = np.zeros_like(U)
    Un[ok] = U[ok] / norm[ok, None]
    return Un, ok


def _assign(score: np.ndarray, camera: np.ndarray, maximize: bool) -> np.ndarray:
    """Per camera, the Hungarian assignment of its rows of ``score`` (``m x k``) to distinct
    columns (``-1`` for a row left over when the camera has more rows than columns)."""
    col = np.full(score.shape[0], -1, dtype=np.int64)
    order = np.argsort(camera, kind="stable")
    cuts = np.flatnonzero(np.diff(camera[order])) + 1
    for rows in np.split(order, cuts):
        if rows.size:
            r, c = linear_sum_assignment(score[rows], maximize=maximize)
            col[rows[r]] = c
    return col


def _check_universe(universe_size) -> None:
    """ValueError unless ``universe_size`` is None or a whole number >= 1 (``"2"``, ``True``
    and ``2.5`` were taken as 2, 1 and 2)."""
    if universe_size is None:
        return
    if isinstance(universe_size, (bool, np.bool_)) or not isinstance(
            universe_size, (int, np.integer)) or universe_size < 1:
        raise ValueError(f"universe_size {universe_size!r}: expected a positive integer or None")


def _by_component(prob: _Problem, spectrum: _Spectrum, counts: np.ndarray,
                  round_block) -> np.ndarray:
    """Labels from rounding each component's ``counts[c]`` leading eigenvectors on its own.

    Equal to rounding the whole embedding at once: an eigenvector lives on one component, so
    a row's cosine with another component's directions is 0. Point ids are numbered through
    the components. A component with one point and no camera twice is that point whole (the
    rounding of a single column, whose Perron eigenvector has one sign, gives the same).
    ``round_block(U, camera) -> (col, keep)``.
    """
    labels = np.full(prob.m_total, -1, dtype=np.int64)
    nxt = 0
    for c in np.flatnonzero(counts).tolist():
        mem, k = prob.members[c], int(counts[c])
        if k == 1 and prob.k_min_comp[c] == 1:
            labels[prob.active[mem]] = nxt
        else:
            col, keep = round_block(spectrum.vectors(c, k), prob.camera[mem])
            labels[prob.active[mem[keep]]] = nxt + col[keep]
        nxt += k
    return labels


# ------------------------------------------------------------------------- baselines


def _first_within(values: np.ndarray, best: float) -> int:
    """The lowest index whose value is within :data:`_TIE` (relative) of ``best``: a choice
    that rounding noise in the last bits of the values cannot change."""
    tol = _TIE * max(1.0, abs(best))
    return int(np.flatnonzero(np.abs(values - best) <= tol)[0])


def _sync_pivots(Un: np.ndarray, cand: np.ndarray, k: int) -> np.ndarray:
    """Rows of ``Un`` (among ``cand``) spanning its row space, as QR with column pivoting
    chooses them: each the row farthest from the span of those chosen before it.

    Ties (every unit row is equally far from an empty span; symmetric inputs) go to the
    lowest id within :data:`_TIE`, not to rounding noise: LAPACK's pivoting breaks them by the
    last bits of the eigenvectors, which differ between BLAS builds and between the dense
    and the ARPACK solver, and a different pivot renames the points (and may move a
    decision). The residual norms are those of Businger–Golub pivoting (``O(m k^2)``)."""
    R = Un[cand].copy()
    piv: list[int] = []
    for _ in range(min(k, cand.size)):
        norm2 = np.einsum("ij,ij->i", R, R)
        norm2[piv] = -1.0
        best = float(norm2.max())
        if best <= _ZERO_ROW ** 2:
            break
        p = _first_within(norm2, best)
        piv.append(p)
        q = R[p] / np.sqrt(norm2[p])
        R -= np.outer(R @ q, q)
    return cand[np.asarray(piv, dtype=np.int64)]


def _round_sync(U: np.ndarray, camera: np.ndarray, min_cosine: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """spectral_sync steps 4-6 on one component's embedding ``U`` (``m_c x k``)."""
    k = U.shape[1]
    Un, ok = _unit_rows(U)
    C = Un[_sync_pivots(Un, np.flatnonzero(ok), k)]           # (k', k), k' = min(k, #cand)
    Z, _, Yt = np.linalg.svd(C, full_matrices=False)
    S = Un @ (Z @ Yt).T                                       # cosines to orthonormal directions
    col = _assign(S, camera, maximize=True)
    got = np.flatnonzero(col >= 0)
    keep = np.zeros(col.size, dtype=bool)
    keep[got] = ok[got] & (S[got, col[got]] > min_cosine)
    return col, keep


def spectral_sync(features_per_camera, links: Links, weight: np.ndarray | None = None,
                  universe_size: int | None = None, *,
                  min_cosine: float = MAJORITY) -> np.ndarray:
    """Permutation synchronization (Pachauri, Kondor, Singh, NIPS 2013), partial visibility.

    Steps (module notes for the notation):

    1. ``W = A + I`` (:func:`association_matrix`), restricted to features with a link.
    2. Universe size: ``universe_size`` points go to the ``universe_size`` leading eigenvalues
       of ``W`` (Pachauri's top-``k`` eigenvectors). When None, each connected component ``c``
       gets ``k_c`` points: the largest eigengap, as a ratio, of its normalized Laplacian
       ``I - D^-1/2 W D^-1/2`` among its eigenvalues below 0.5, at least the most features of
       one camera in it (:func:`universe_size_gap`).
    3. ``U`` = the leading eigenvectors of ``W`` (Pachauri et al., Alg. 1: for consistent
       links ``W = X X^T`` and ``U`` spans the columns of ``X``). Every row of ``U`` is scaled
       to length 1: then all features of one universe point share one row (``X``'s rows are
       unit vectors, mixed by an orthogonal ``k x k`` matrix).
    4. Representatives: the first ``k`` pivots of the column-pivoted QR of the normalized
       ``U^T`` (Damle–Minden–Ying, Alg. 1 — the most linearly independent rows, one per point
       in the consistent case), their directions made exactly orthonormal by the polar
       factor ``R`` of their rows (closest orthogonal matrix, ``C = Z S Y^T -> R = Z Y^T``).
    5. Scores ``S = U R^T``: each row's cosines to the ``k`` directions; their squares sum to
       1 (a row's energy split over the points). Per camera, the Hungarian method
       (``linear_sum_assignment``, maximizing) assigns its features to distinct points —
       Pachauri's ``argmax_P <P, U_i U_1^T>`` with the representatives for image 1.
    6. Unassigned (``-1``): a feature whose assigned cosine is at most ``min_cosine``,
       by default ``1/sqrt(2)`` (:data:`MAJORITY` — less than half of its energy on that
       point; more than half can lie on one point only; ``min_cosine=-1`` keeps every
       assignment, as Pachauri et al. do with full visibility), a feature without a link,
       a feature whose row of ``U`` is zero (its component got no point), or one left over
       when its camera has more features than points.

    Steps 3-6 run per connected component (:func:`_by_component`, same result).

    Parameters
    ----------
    features_per_camera : (n,) int
    links : Links, (L,)
    weight : (L,) float >= 0 or None — link weights (None: every link 1)
    universe_size : int or None — number of universe points ``k`` (None: estimated, step 2)
    min_cosine : float — the least cosine of a kept assignment (step 6)

    Returns
    -------
    labels : ndarray, (m_total,) int64 — universe point of every feature, ``-1`` unassigned;
        no two features of one camera share a label ``>= 0``

    Examples
    --------
    Three cameras see points A (features 0:0, 1:1, 2:0) and B (0:1, 1:0, 2:1); every pair
    of cameras is matched, and one wrong link 0:0 - 1:0 is added:

    >>> links = Links([0, 0, 1, 0, 0, 1, 0], [0, 0, 1, 1, 1, 0, 0],
    ...               [1, 2, 2, 1, 2, 2, 1], [1, 0, 0, 0, 1, 1, 0])
    >>> spectral_sync([2, 2, 2], links).tolist()     # A = global ids 0, 3, 4; B = 1, 2, 5
    [0, 1, 1, 0, 0, 1]
    """
    _check_universe(universe_size)
    if not -1.0 <= float(min_cosine) <= 1.0:  # nan too: it left every feature unassigned
        raise ValueError(f"min_cosine {min_cosine!r}: expected a cosine in [-1, 1]")
    prob = _problem(features_per_camera, links, weight)
    if prob.active.size == 0:
        return np.full(prob.m_total, -1, dtype=np.int64)
    spectrum = _Spectrum(prob.W, prob)
    if universe_size is None:
        normalized = _Spectrum(_normalized(prob.W), prob, keep_vectors=False)
        heads = normalized.down_to(1.0 - CLEAR_THRESHOLD, 2 * prob.k_min_comp + 2)
        counts = np.array([universe_size_gap(mu, int(kc))
                           for mu, kc in zip(heads, prob.k_min_comp.tolist(), strict=True)])
    else:
        counts = spectrum.top_counts(int(universe_size))
    return _by_component(prob, spectrum, counts,
                         lambda U, cam: _round_sync(U, cam, float(min_cosine)))


def _clear_pivots(U: np.ndarray, Un: np.ndarray, ok: np.ndarray, k: int) -> np.ndarray:
    """CLEAR's cluster centres: greedy rows with the least total ``|cosine|`` to those chosen.

    CLEAR's code starts from the first row; here from the row of ``U`` with the largest norm
    (lowest id on ties), so the choice does not depend on the order of the features. Each
    further pivot minimizes the sum of ``|<u_r, u_p>|`` over the pivots ``p`` already chosen
    (``O(m k)`` per pivot, no ``m x m`` matrix). Ties are ties within :data:`_TIE`
    (:func:`_first_within`), so rounding noise of the eigenvectors does not choose.
    """
    norm = np.linalg.norm(U, axis=1)
    norm[~ok] = -1.0
    piv = [_first_within(norm, float(norm.max()))]
    total = np.abs(Un @ Un[piv[0]])
    total[~ok] = np.inf
    total[piv[0]] = np.inf
    for _ in range(1, min(k, int(ok.sum()))):
        p = _first_within(total, float(total.min()))
        piv.append(p)
        total += np.abs(Un @ Un[p])
        total[p] = np.inf
    return np.asarray(piv, dtype=np.int64)


def _round_clear(U: np.ndarray, camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """clear_sync steps 5-7 on one component's embedding ``U`` (``m_c x k``)."""
    Un, ok = _unit_rows(U)
    C = Un[_clear_pivots(U, Un, ok, U.shape[1])]
    col = _assign(1.0 - Un @ C.T, camera, maximize=False)
    return col, ok & (col >= 0)


def clear_sync(features_per_camera, links: Links, weight: np.ndarray | None = None,
               universe_size: int | None = None) -> np.ndarray:
    """A CLEAR-style multi-view association (Fathian et al., IEEE T-RO 2020, Alg. 1).

    Steps, in CLEAR's terms:

    1. Association graph: ``W = A + I`` (:func:`association_matrix`; CLEAR's aggregate matrix
       ``P`` symmetrized, its diagonal blocks set to ``I``), features with a link only.
    2. Normalized Laplacian ``L_nrm = (D + I)^-1/2 (D - A) (D + I)^-1/2 = I - N`` with
       ``N = D_W^-1/2 W D_W^-1/2``, ``D`` the degrees of ``A`` and ``D_W = D + I`` those of
       ``W`` (CLEAR's "DI" normalization, symmetric).
    3. Universe size ``k`` = ``universe_size``, or the number of eigenvalues of ``L_nrm`` below
       :data:`CLEAR_THRESHOLD` = 0.5, at least the most linked features of one camera
       (:func:`universe_size_count`, which gives the reason for 0.5).
    4. Spectral embedding: the ``k`` eigenvectors of ``L_nrm`` of smallest eigenvalue (its
       near-kernel; the ``k`` largest of ``N``), rows scaled to length 1 (``U``).
    5. Cluster centres ``C``: ``k`` pivot rows of ``U``, greedily the least aligned with those
       already chosen (:func:`_clear_pivots`).
    6. Alignment: distances ``F = 1 - U C^T``; each camera's features assigned to distinct
       centres by the Hungarian method (CLEAR's code uses a greedy approximation of it).
    7. Rectification: the lifting ``X`` (one 1 per assigned row, distinct columns within a
       camera) gives the consistent pairwise association ``X X^T`` — here the labels.
       As published, every linked feature is assigned (no score threshold); ``-1`` only for
       a feature without links, a zero row of the embedding (its component got no
       eigenvector), or one left over when its component has fewer centres than its camera
       has features there.

    Steps 5-7 run per connected component (:func:`_by_component`): an eigenvector lives on
    one component, so a centre of another is at distance 1 from every row (CLEAR's global
    pivot search and assignment can only pair such rows at random).

    Parameters and return value as :func:`spectral_sync` (no ``min_cosine``).

    Examples
    --------
    Three cameras see points A (features 0:0, 1:1, 2:0) and B (0:1, 1:0, 2:1); every pair
    of cameras is matched, and one wrong link 0:0 - 1:0 is added:

    >>> links = Links([0, 0, 1, 0, 0, 1, 0], [0, 0, 1, 1, 1, 0, 0],
    ...               [1, 2, 2, 1, 2, 2, 1], [1, 0, 0, 0, 1, 1, 0])
    >>> clear_sync([2, 2, 2], links).tolist()     # A = global ids 0, 3, 4; B = 1, 2, 5
    [1, 0, 0, 1, 1, 0]
    """
    _check_universe(universe_size)
    prob = _problem(features_per_camera, links, weight)
    if prob.active.size == 0:
        return np.full(prob.m_total, -1, dtype=np.int64)
    spectrum = _Spectrum(_normalized(prob.W), prob)
    if universe_size is None:
        heads = spectrum.down_to(1.0 - CLEAR_THRESHOLD, 2 * prob.k_min_comp + 2)
        k = universe_size_count(np.concatenate(heads), prob.k_min)
    else:
        k = int(universe_size)
    counts = spectrum.top_counts(min(k, prob.active.size))
    return _by_component(prob, spectrum, counts, _round_clear)


def labels_to_kept(features_per_camera, links: Links, labels: np.ndarray) -> np.ndarray:
    """Kept mask ``(L,)`` of the links an association by labels keeps: both ends share a
    label ``>= 0``.

    Examples
    --------
    >>> labels_to_kept([1, 1, 1], Links([0, 0], [0, 0], [1, 2], [0, 0]), np.array([4, 4, -1]))
    array([ True, False])
    """
    a, b = _link_ends(features_per_camera, links)
    labels = np.asarray(labels, dtype=np.int64)
    m_total = int(np.sum(features_per_camera))
    if labels.shape != (m_total,):
        raise ValueError(f"labels of shape {labels.shape}: expected ({m_total},), one per "
                         "feature")
    return (labels[a] == labels[b]) & (labels[a] >= 0)
