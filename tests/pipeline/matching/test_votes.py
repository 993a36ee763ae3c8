"""Two-hop vote refinement: a wrong match outvoted by its triangles, nothing to vote on a
ring, one-to-one output on comm edges only, messages counted."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.association import check_links
from pipeline.matching.votes import refine_by_votes
from pipeline.types import Links


def _identity_links(edges, K, wrong=None):
    """Identity matches on every edge; ``wrong`` = the edge whose landmarks 0 and 1 swap."""
    ci, fi, cj, fj = [], [], [], []
    for i, j in edges:
        perm = np.arange(K)
        if wrong == (i, j):
            perm[[0, 1]] = [1, 0]
        ci += [i] * K
        fi += list(range(K))
        cj += [j] * K
        fj += perm.tolist()
    return Links(ci, fi, cj, fj)


def _as_set(links):
    return set(zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                   links.feat_j.tolist(), strict=True))


def test_swap_is_outvoted_on_a_complete_graph():
    edges = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    links = _identity_links(edges, 3, wrong=(0, 2))
    refined, stats = refine_by_votes([3] * 4, np.array(edges), links)
    assert _as_set(refined) == _as_set(_identity_links(edges, 3))
    assert stats["fixed_point"] and stats["changed_per_iteration"][-1] == 0
    assert stats["changed_per_iteration"][0] == 2  # the two swapped matches
    assert stats["messages"] > 0 and stats["bytes"] > 0
    assert stats["rounds"] == 2 * stats["iterations"]


def test_ring_has_no_common_neighbours_so_nothing_changes():
    edges = [(0, 1), (1, 2), (2, 3), (0, 3)]
    links = _identity_links(edges, 4, wrong=(1, 2))
    refined, stats = refine_by_votes([4] * 4, np.array(edges), links)
    assert _as_set(refined) == _as_set(links)
    assert stats["changed_per_iteration"] == [0]


def test_tie_between_direct_link_and_one_path_drops_both():
    """Three robots: the swapped edge has one direct vote and one two-hop vote per row."""
    edges = [(0, 1), (0, 2), (1, 2)]
    links = _identity_links(edges, 3, wrong=(0, 2))
    refined, _ = refine_by_votes([3] * 3, np.array(edges), links, iterations=1)
    on_02 = {(r, s) for c, r, d, s in _as_set(refined) if (c, d) == (0, 2)}
    assert on_02 == {(2, 2)}  # landmarks 0 and 1: no majority either way


def _random_matches(rng, n, K, p_edge):
    """Random one-to-one matches of up to ``K`` landmarks on each edge of a random graph of
    ``n`` robots (each pair an edge with probability ``p_edge``): ``(edges, ci, fi, cj, fj)``."""
    edges = [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < p_edge]
    if not edges:
        edges = [(0, 1)]
    ci, fi, cj, fj = [], [], [], []
    for i, j in edges:
        k = int(rng.integers(0, K + 1))
        r, s = rng.permutation(K)[:k], rng.permutation(K)[:k]
        ci += [i] * k
        fi += r.tolist()
        cj += [j] * k
        fj += s.tolist()
    return edges, ci, fi, cj, fj


@settings(max_examples=25, deadline=None)
@given(st.integers(3, 6), st.integers(1, 5), st.integers(0, 10_000))
def test_output_is_one_to_one_on_comm_edges(n, K, seed):
    edges, ci, fi, cj, fj = _random_matches(np.random.default_rng(seed), n, K, 0.7)
    refined, _ = refine_by_votes([K] * n, np.array(edges), Links(ci, fi, cj, fj), iterations=3)
    check_links(refined, [K] * n)
    assert {(a, b) for a, _, b, _ in _as_set(refined)} <= set(edges)


def test_refined_links_keep_the_input_quality():
    """The votes decide which pairs are matched; the refined links carry the descriptor
    evidence of their pair (not the vote share, which is 1 for nearly every kept pair and
    left a weighing rule with ties only), and a pair the votes introduced gets quality 0."""
    edges = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    links = _identity_links(edges, 3, wrong=(0, 2))
    quality = np.linspace(0.3, 0.9, len(links))
    links = Links(links.cam_i, links.feat_i, links.cam_j, links.feat_j, quality)
    given_q = dict(zip(zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                           links.feat_j.tolist(), strict=True), quality.tolist(), strict=True))
    refined, _ = refine_by_votes([3] * 4, np.array(edges), links)
    got = dict(zip(zip(refined.cam_i.tolist(), refined.feat_i.tolist(),
                       refined.cam_j.tolist(), refined.feat_j.tolist(), strict=True),
                   refined.quality.tolist(), strict=True))
    introduced = {(0, 0, 2, 0), (0, 1, 2, 1)}  # the votes undid the swap on edge (0, 2)
    assert set(got) - set(given_q) == introduced
    assert all(got[k] == 0.0 for k in introduced)
    assert all(got[k] == given_q[k] for k in set(got) - introduced)


@settings(max_examples=25, deadline=None)
@given(st.integers(3, 6), st.integers(1, 5), st.integers(0, 10_000))
def test_a_refined_link_has_its_input_quality_or_zero(n, K, seed):
    rng = np.random.default_rng(seed)
    edges, ci, fi, cj, fj = _random_matches(rng, n, K, 0.8)
    q = rng.uniform(0.1, 0.9, len(ci))
    links = Links(ci, fi, cj, fj, q)
    refined, _ = refine_by_votes([K] * n, np.array(edges), links, iterations=3)
    given_q = dict(zip(zip(ci, fi, cj, fj, strict=True), q.tolist(), strict=True))
    for key, quality in zip(zip(refined.cam_i.tolist(), refined.feat_i.tolist(),
                                refined.cam_j.tolist(), refined.feat_j.tolist(), strict=True),
                            refined.quality.tolist(), strict=True):
        assert quality == given_q.get(key, 0.0)
