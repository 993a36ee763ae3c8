"""Array helpers of the batched simulator engines: sorted int64 keys and index ranges.

Pure NumPy, shared by :mod:`.batched`, :mod:`.batched_resolution` and
:mod:`.batched_evidence` (they compute on sorted keys such as ``row * A + col`` because
sorting beats hashing at these sizes).
"""

from __future__ import annotations

import numpy as np

__all__ = ["EMPTY", "isin_sorted", "ranges"]

#: an empty int64 index array
EMPTY = np.zeros(0, dtype=np.int64)


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
