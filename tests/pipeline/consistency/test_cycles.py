"""Short-cycle support (pipeline.consistency.cycles): what one robot computes from its own
links and its neighbours' lists equals a brute-force count over the whole graph, and the two
ends of a link agree."""

from itertools import combinations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.consistency.cycles import SUPPORT_VIEWS, cycle_support, shared_cameras, support_term


def _graph(seed: int, n: int, m: int, p: float):
    rng = np.random.default_rng(seed)
    edges = set()
    for i, j in combinations(range(n), 2):
        if rng.random() < p:
            a, b = rng.permutation(m), rng.permutation(m)
            k = rng.integers(1, m + 1)
            edges.update((i * m + int(x), j * m + int(y)) for x, y in zip(a[:k], b[:k],
                                                                          strict=True))
    return edges


def _brute(edges, m, r, s):
    nbr = {}
    for a, b in edges:
        nbr.setdefault(a, set()).add(b)
        nbr.setdefault(b, set()).add(a)
    cam = lambda g: g // m  # noqa: E731
    tau = len({cam(u) for u in nbr[r] & nbr[s]})
    quad = any(u in nbr[s] and len({cam(r), cam(t), cam(u), cam(s)}) == 4
               for t in nbr[r] - {s} for u in nbr.get(t, ()))
    return tau, (quad and tau == 0)


def _robot_view(edges, m, i):
    """What robot i holds after the support round: its links and its neighbours' lists."""
    nbr = {}
    for a, b in edges:
        nbr.setdefault(a, set()).add(b)
        nbr.setdefault(b, set()).add(a)
    own = [(a, b) if a // m == i else (b, a) for a, b in edges if i in (a // m, b // m)]
    own_lists = {r: np.array(sorted(nbr[r]), dtype=np.int64) for r, _ in own}
    lists = {t: np.array(sorted(nbr[t]), dtype=np.int64) for r, _ in own for t in nbr[r]}
    return own, own_lists, lists


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 6), m=st.integers(1, 4),
       p=st.sampled_from([0.5, 0.8, 1.0]))
def test_a_robots_counts_are_the_whole_graphs(seed, n, m, p):
    edges = _graph(seed, n, m, p)
    for i in range(n):
        own, own_lists, lists = _robot_view(edges, m, i)
        if not own:
            continue
        r = np.array([a for a, _ in own], dtype=np.int64)
        s = np.array([b for _, b in own], dtype=np.int64)
        tau, quad = cycle_support(r, s, lists, own_lists, lambda g: np.asarray(g) // m)
        want = [_brute(edges, m, a, b) for a, b in own]
        assert tau.tolist() == [t for t, _ in want]
        assert quad.tolist() == [q for _, q in want]


def test_a_good_link_next_to_a_swap_keeps_a_quadrangle():
    # five cameras in a row, one landmark A (feature 0) and B (feature 1) each; every camera
    # linked to the next two (ring2 without the wrap); cameras 1 and 2 swapped A and B
    m = 2
    edges = set()
    for i in range(5):
        for j in (i + 1, i + 2):
            if j < 5:
                for k in range(2):
                    t = 1 - k if (i, j) == (1, 2) else k
                    edges.add((i * m + k, j * m + t))
    # A1-A3 (good) lost its triangle through camera 2 (A1~B2, A3~A2); A0-A2 likewise
    for a, b in ((2, 6), (0, 4)):
        assert _brute(edges, m, a, b) == (0, True)
    # the swapped A1-B2 closes neither
    assert _brute(edges, m, 2, 5) == (0, False)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 7), m=st.integers(1, 5),
       p=st.floats(0.2, 1.0))
def test_shared_cameras_equal_a_brute_force_count(seed, n, m, p):
    edges = sorted(_graph(seed, n, m, p))
    if not edges:
        return
    a = np.array([x for x, _ in edges], dtype=np.int64)
    b = np.array([y for _, y in edges], dtype=np.int64)
    nbr = {}
    for x, y in edges:
        nbr.setdefault(x, set()).add(y // m)
        nbr.setdefault(y, set()).add(x // m)
    want = [len(nbr[x] & nbr[y]) for x, y in edges]
    assert shared_cameras(a, b, a // m, b // m).tolist() == want


def test_support_term_counts_triangles_up_to_k_then_the_agreement_rate():
    k = SUPPORT_VIEWS
    tau = np.array([0, 0, 2, k, k, 2 * k, 0])
    shared = np.array([0, 3, 2, k, 2 * k, 4 * k, 4 * k])
    quad = np.array([True, False, True, False, False, False, True])
    got = support_term(tau, shared, quad)
    # a quadrangle counts one only without triangle; beyond K shared cameras: K · τ / shared
    np.testing.assert_allclose(got, [1.0, 0.0, 2.0, k, k / 2, k / 2, 1.0], rtol=0, atol=1e-12)
