"""The fused point of each track against its definition written out per track: the
connected groups of observers holding a valid estimate (a breadth-first search over the
observer graph), the largest (ties: the one holding the lowest such robot), the most common
winner in it (ties: the lowest hypothesis), the mean of those robots' estimates."""

import numpy as np
import pytest

from pipeline.fusion.points import fused_points


def by_hand(edges, good, theta, winner, K):
    n = len(good)
    nb = {i: set() for i in range(n)}
    for a, b in edges:
        nb[a].add(b)
        nb[b].add(a)
    seen, groups = set(), []
    for s in range(n):
        if s in seen:
            continue
        comp, todo = set(), [s]
        while todo:
            a = todo.pop()
            if a in comp:
                continue
            comp.add(a)
            todo += list(nb[a])
        seen |= comp
        g = sorted(i for i in comp if good[i])
        if g:
            groups.append(g)
    if not groups:
        return None, np.zeros(n, bool), False
    best = min(groups, key=lambda g: (-len(g), g[0]))
    counts = np.bincount([winner[i] for i in best], minlength=K)
    w = int(np.argmax(counts))
    used = [i for i in best if winner[i] == w]
    grp = np.zeros(n, bool)
    grp[used] = True
    return theta[used].mean(0), grp, int((counts > 0).sum()) > 1


@pytest.mark.parametrize("seed", range(6))
def test_fused_points_equal_the_definition(seed):
    rng = np.random.default_rng(seed)
    B, n, K = 30, 6, 3
    node_edges, per_track = [], []
    for b in range(B):
        e = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.25]
        per_track.append(e)
        node_edges += [(b * n + i, b * n + j) for i, j in e]
    node_edges = np.array(node_edges, dtype=np.int64).reshape(-1, 2)
    good = rng.random((B, n)) < 0.6
    theta = rng.normal(size=(B, n, 3))
    winner = rng.integers(0, K, (B, n))
    res = fused_points(node_edges, good, theta, winner, K)
    for b in range(B):
        pt, grp, split = by_hand(per_track[b], good[b], theta[b], winner[b], K)
        assert res.has_point[b] == (pt is not None)
        np.testing.assert_array_equal(res.group[b], grp)
        if pt is not None:
            np.testing.assert_allclose(res.points[b], pt, rtol=1e-12, atol=1e-12)
            assert res.split[b] == split
