"""Random ``sync`` instances with planted conflicts (shared by the ``sync`` tests)."""

from itertools import combinations

import numpy as np

from pipeline.types import Links


def planted_instance(seed: int, n: int, m: int, p_link: float, p_swap: float, ties: bool,
                     graph: str = "complete"):
    """``n`` cameras seeing the same ``m`` landmarks (feature order shuffled per camera), every
    pair of the graph (``complete``, or ``ring2``: ``i`` with ``i + 1`` and ``i + 2`` mod
    ``n``) matched one-to-one with probability ``p_link`` per landmark; on a pair, with
    probability ``p_swap`` two matches are swapped (wrong links that make conflicts).
    Evidence: integers 0..2 (``ties``) or standard normal. Returns ``fpc, links, weight``."""
    rng = np.random.default_rng(seed)
    perm = [rng.permutation(m) for _ in range(n)]  # perm[i][k]: feature of landmark k in i
    if graph == "ring2":
        pairs = sorted({(min(i, (i + d) % n), max(i, (i + d) % n))
                        for i in range(n) for d in (1, 2) if (i + d) % n != i})
    else:
        pairs = list(combinations(range(n), 2))
    ci, fi, cj, fj, w = [], [], [], [], []
    for i, j in pairs:
        ks = np.flatnonzero(rng.random(m) < p_link)
        tgt = ks.copy()
        if ks.size >= 2 and rng.random() < p_swap:
            a, b = rng.choice(ks.size, 2, replace=False)
            tgt[a], tgt[b] = tgt[b], tgt[a]
        for k, t in zip(ks.tolist(), tgt.tolist(), strict=True):
            ci.append(i), fi.append(int(perm[i][k])), cj.append(j), fj.append(int(perm[j][t]))
            w.append(float(rng.integers(0, 3)) if ties else float(rng.normal()))
    fpc = np.full(n, m, dtype=np.int64)
    return fpc, Links(ci, fi, cj, fj), np.array(w)


def comm_edges(links: Links) -> np.ndarray:
    """The camera pairs that hold a link, ``(E, 2)`` int64."""
    return np.array(sorted({(int(i), int(j)) for i, j in zip(links.cam_i, links.cam_j,
                                                              strict=True)}),
                    dtype=np.int64).reshape(-1, 2)


def irregular_instance(seed: int, n: int, max_m: int, p_pair: float, p_link: float,
                       weights: str):
    """``n`` cameras of 0..``max_m`` features each; each camera pair (with probability
    ``p_pair``) matches a random one-to-one subset of their features, each match kept with
    probability ``p_link`` (cameras without links, several components, conflicts by chance).
    Evidence ``weights``: ``ties`` (0 or 1), ``equal`` (all 0), ``normal``, ``inf`` (+-inf).
    Returns ``fpc, links, weight``."""
    rng = np.random.default_rng(seed)
    fpc = rng.integers(0, max_m + 1, n)
    ci, fi, cj, fj = [], [], [], []
    for i, j in combinations(range(n), 2):
        if rng.random() >= p_pair:
            continue
        k = int(min(fpc[i], fpc[j]))
        for x, y in zip(rng.permutation(fpc[i])[:k].tolist(), rng.permutation(fpc[j])[:k].tolist(),
                        strict=True):
            if rng.random() < p_link:
                ci.append(i), fi.append(x), cj.append(j), fj.append(y)
    L = len(ci)
    weight = {"ties": lambda: rng.integers(0, 2, L).astype(float), "equal": lambda: np.zeros(L),
              "normal": lambda: rng.normal(size=L),
              "inf": lambda: np.where(rng.random(L) < 0.5, np.inf, -np.inf)}[weights]()
    return fpc, Links(ci, fi, cj, fj), weight
