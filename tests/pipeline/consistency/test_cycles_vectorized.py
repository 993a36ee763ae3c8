"""The cycle support of the sync rule is evaluated for all links at once: a per-link Python
loop took most of a 350,000-match clean-h5 run (46 s) and minutes on a million matches."""

import numpy as np

from pipeline.consistency.cycles import cycle_support


def _ring2(n_cams, m):
    """Every camera linked to the next two by each of its ``m`` features; cameras 0 and 1
    swapped their matches (links without a triangle)."""
    nbr = {}
    for i in range(n_cams):
        for j in (i + 1, i + 2):
            if j < n_cams:
                for k in range(m):
                    t = (k + 1) % m if (i, j) == (0, 1) else k
                    a, b = i * m + k, j * m + t
                    nbr.setdefault(a, []).append(b)
                    nbr.setdefault(b, []).append(a)
    return {g: np.array(sorted(v), dtype=np.int64) for g, v in nbr.items()}


def test_camera_of_is_called_a_few_times_not_once_per_link():
    m = 20
    lists = _ring2(12, m)
    own = np.array([g for g, v in lists.items() for _ in v], dtype=np.int64)
    far = np.concatenate(list(lists.values()))
    calls = []

    def camera_of(g):
        calls.append(1)
        return np.asarray(g) // m

    tau, quad = cycle_support(own, far, lists, lists, camera_of)
    assert own.size > 400
    assert len(calls) <= 10
    assert (tau[own // m + far // m == 1] == 0).all()  # the swapped pair: no triangle
    assert tau.any() and not quad[tau > 0].any()  # quadrangles only where no triangle


def test_pieces_give_the_result_of_one_piece():
    from pipeline.consistency.cycles import CHUNK, cycle_support_rows

    m = 5
    lists = _ring2(9, m)
    own = np.array([g for g, v in lists.items() for _ in v], dtype=np.int64)
    far = np.concatenate(list(lists.values()))
    keys = np.array(sorted(lists), dtype=np.int64)
    ptr = np.concatenate([[0], np.cumsum([lists[int(k)].size for k in keys])])
    rows = (keys, ptr, np.concatenate([lists[int(k)] for k in keys]))
    whole = cycle_support_rows(own, far, rows, rows, lambda g: np.asarray(g) // m, CHUNK)
    small = cycle_support_rows(own, far, rows, rows, lambda g: np.asarray(g) // m, 3)
    assert np.array_equal(whole[0], small[0]) and np.array_equal(whole[1], small[1])
