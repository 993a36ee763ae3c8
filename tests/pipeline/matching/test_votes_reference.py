"""Two-hop vote refinement against the module's equation evaluated with dense matrices:
``W_ij = A_ij + Σ_{k ∈ N_i ∩ N_j} A_ik A_kj``, a maximum-weight assignment on ``W_ij``, and
a pair kept only with a strict majority of its row and of its column; every edge from the
matches at the start of the iteration, iterated to the same count. Robots hold different
numbers of landmarks."""

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from pipeline.matching.votes import refine_by_votes
from pipeline.types import Links


def random_instance(seed):
    rng = np.random.default_rng(seed)
    n = 5
    m = rng.integers(4, 8, n)
    edges = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.7]
    if not edges:
        edges = [(0, 1)]
    A = {}
    for i, j in edges:
        # a partial one-to-one match: mostly the identity on the common landmarks, some noise
        k = min(m[i], m[j])
        perm = np.arange(k)
        if rng.random() < 0.6:
            a, b = rng.choice(k, 2, replace=False)
            perm[[a, b]] = perm[[b, a]]
        M = np.zeros((m[i], m[j]))
        keep = rng.random(k) < 0.8
        M[np.arange(k)[keep], perm[keep]] = 1.0
        A[i, j] = M
    return m, edges, A, rng


def one_iteration(m, edges, A):
    nb = {i: set() for i in range(len(m))}
    for i, j in edges:
        nb[i].add(j)
        nb[j].add(i)

    def get(a, b):
        return A[a, b] if (a, b) in A else A[b, a].T

    new = {}
    for i, j in edges:
        W = get(i, j).copy()
        for k in sorted(nb[i] & nb[j]):
            W += get(i, k) @ get(k, j)
        M = np.zeros_like(W)
        if W.any():
            r, s = linear_sum_assignment(W, maximize=True)
            w = W[r, s]
            ok = (w > 0) & (2 * w > W.sum(1)[r]) & (2 * w > W.sum(0)[s])
            M[r[ok], s[ok]] = 1.0
        new[i, j] = M
    return new


def as_links(A, quality):
    ci, fi, cj, fj, q = [], [], [], [], []
    for (i, j), M in sorted(A.items()):
        r, s = np.nonzero(M)
        ci += [i] * len(r)
        cj += [j] * len(r)
        fi += r.tolist()
        fj += s.tolist()
        q += [quality.get((i, a, j, b), 0.0) for a, b in zip(r.tolist(), s.tolist(), strict=True)]
    return Links(ci, fi, cj, fj, q)


def as_table(links):
    return sorted(zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                      links.feat_j.tolist(), np.round(links.quality, 12).tolist(), strict=True))


@pytest.mark.parametrize("iterations", [1, 2, 4])
@pytest.mark.parametrize("seed", range(12))
def test_votes_equal_dense_matrices(seed, iterations):
    m, edges, A, rng = random_instance(seed)
    links = as_links(A, {})
    links.quality = rng.uniform(0.1, 0.9, len(links))
    # a kept pair keeps its input quality, a pair the votes introduced gets 0
    quality = dict(zip(zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                           links.feat_j.tolist(), strict=True), links.quality.tolist(),
                       strict=True))
    want = A
    for _ in range(iterations):
        nxt = one_iteration(m, edges, want)
        same = all(np.array_equal(nxt[e], want[e]) for e in edges)
        want = nxt
        if same:
            break
    refined, _ = refine_by_votes(m.tolist(), np.array(edges), links, iterations=iterations)
    assert as_table(refined) == as_table(as_links(want, quality))


def test_the_instances_change_under_the_votes():
    changed = 0
    for seed in range(12):
        m, edges, A, _ = random_instance(seed)
        new = one_iteration(m, edges, A)
        changed += sum(not np.array_equal(new[e], A[e]) for e in edges)
    assert changed >= 6
