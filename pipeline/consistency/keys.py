"""Array helpers of the batched simulator engines: sorted int64 keys and index ranges.

Pure NumPy, shared by :mod:`.batched`, :mod:`.batched_resolution` and
:mod:`.batched_evidence` (they compute on sorted keys such as ``row * A + col`` because
sorting beats hashing at these sizes).
"""

from __future__ import annotations

import numpy as np

__all__ = ["EMPTY", "isin_sorted", "ranges", "tie_key", "unique"]

#: an empty int64 index array
EMPTY = np.zeros(0, dtype=np.int64)


def unique(a: np.ndarray) -> np.ndarray:
    """``np.unique(a)`` of a flat array, by sorting: NumPy 2.4's ``np.unique`` without
    ``return_*`` hashes, 10-20 times slower on millions of int64 keys (4 M random keys:
    11 s against 0.5 s), which made it most of a large ``sync`` run.

    >>> unique(np.array([3, 1, 3, 2]))
    array([1, 2, 3])
    """
    s = np.sort(np.asarray(a).reshape(-1))
    if s.size < 2:
        return s
    keep = np.empty(s.size, dtype=bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]


def isin_sorted(q: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``np.isin(q, a)`` for ``a`` sorted, by binary search; (len(q),) bool.

    >>> isin_sorted(np.array([3, 4, 9]), np.array([1, 3, 9]))
    array([ True, False,  True])
    """
    if a.size == 0 or q.size == 0:
        return np.zeros(q.shape, dtype=bool)
    pos = np.minimum(np.searchsorted(a, q), a.size - 1)
    return a[pos] == q


def ranges(start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(start[k], stop[k])`` over ``k``.

    >>> ranges(np.array([0, 5]), np.array([2, 8]))
    array([0, 1, 5, 6, 7])
    """
    length = stop - start
    total = int(length.sum())
    if total == 0:
        return EMPTY
    first = np.cumsum(length) - length
    return np.repeat(start - first, length) + np.arange(total)


_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def _mix(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser on uint64 (wrapping arithmetic)."""
    x = (x ^ (x >> np.uint64(30))) * _M1
    x = (x ^ (x >> np.uint64(27))) * _M2
    return x ^ (x >> np.uint64(31))


def tie_key(lo, hi) -> np.ndarray:
    """A fixed pseudo-random uint64 per link ``(lo, hi)`` (its two global feature ids): the
    merge rules order links of equal evidence by it (smaller first), then by ``lo``, ``hi``.

    Both ends of a link compute it alike from public ids. Ordering ties by the ids instead
    makes a chain of equal links sequential for the distributed merge: on a path every
    cluster prefers the link towards smaller ids, so each Borůvka round of :mod:`.sync`
    merges one pair and a cycle of ``n`` cameras took about ``n²`` rounds (996,006 at
    ``n = 1000``); in a pseudo-random order a constant share of the links is locally dominant
    in every round.

    >>> k = tie_key(np.array([0, 0, 5]), np.array([1, 2, 9]))
    >>> k.dtype, bool(k[0] != k[1]), int(tie_key(np.array([0]), np.array([1]))[0]) == int(k[0])
    (dtype('uint64'), True, True)
    """
    lo = np.asarray(lo).astype(np.int64).astype(np.uint64)
    hi = np.asarray(hi).astype(np.int64).astype(np.uint64)
    with np.errstate(over="ignore"):
        return _mix(_mix(lo) ^ hi)
