"""The batched detection's memory follows its result, not the paths to it: eq. (5)'s product
``P Δ`` listed every (reader, entry) pair and then removed the repeats, one key per path, about
``deg`` times the result on a dense graph (the 101-frame hotel input, descriptors only, on the
complete graph: 7.6 GB at the peak, where ``paper``'s own state is a few hundred MB). A round of
more than ``EXPAND_KEYS_MAX`` pairs is now SciPy's sparse product of boolean matrices, with the
same keys."""

import tracemalloc
from unittest.mock import patch

import numpy as np
from consistency_graphs import instances
from hypothesis import HealthCheck, given, settings

from pipeline.commgraph import comm_edges_for
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.engines import batched
from pipeline.types import Links


def _dense_team(n: int, k: int, swaps: int, seed: int = 0):
    """``n`` cameras on the complete graph, each seeing ``k`` landmarks (feature ``f`` of every
    camera is landmark ``f``), every pair linked; ``swaps`` pairs swap two of their matches."""
    rng = np.random.default_rng(seed)
    ci, fi, cj, fj = [], [], [], []
    pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
    swapped = set(rng.choice(len(pairs), swaps, replace=False).tolist())
    for p, (a, b) in enumerate(pairs):
        to = np.arange(k)
        if p in swapped:
            x, y = rng.choice(k, 2, replace=False)
            to[[x, y]] = to[[y, x]]
        ci += [a] * k
        fi += list(range(k))
        cj += [b] * k
        fj += to.tolist()
    m = np.full(n, k, dtype=np.int64)
    return m, Links(np.array(ci), np.array(fi), np.array(cj), np.array(fj))


def test_paper_detection_on_a_dense_team_holds_its_result_not_every_path():
    """At this team's scale the listing stops at 2^16 pairs (2^22 by default, for 64 times
    larger teams): the rest of each round is one sparse product."""
    m, links = _dense_team(40, 30, swaps=8)
    edges = comm_edges_for(m, links, None)
    tracemalloc.start()
    try:
        with patch.object(batched, "EXPAND_KEYS_MAX", 1 << 16):
            res = resolve_conflicts(m, edges, links, resolution="paper")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # one set of 1200 features: 1.44 M keys of X (11.5 MB as int64, less in runs); measured
    # 7.8 MB at the peak with every round a product, 80 MB with every round listed
    assert peak < 30e6, peak
    assert res.stats["detection_rounds"] > 0
    kept = ~res.deleted
    assert kept.sum() > 0.9 * len(links.cam_i)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances(max_n=7, max_feat=4))
def test_the_product_and_the_listing_give_the_same_detection(inst):
    """Every round a product (no listing at all) gives exactly what every round listed gives:
    the same cuts, rounds, messages and bytes."""
    fpc, edges, links = inst
    listed = resolve_conflicts(fpc, edges, links, resolution="paper")
    with patch.object(batched, "EXPAND_KEYS_MAX", -1):
        product = resolve_conflicts(fpc, edges, links, resolution="paper")
    np.testing.assert_array_equal(listed.deleted, product.deleted)
    np.testing.assert_array_equal(listed.track_label, product.track_label)
    for k in ("detection_rounds", "resolution_rounds", "messages", "bytes",
              "max_robot_memory_bytes"):
        assert listed.stats[k] == product.stats[k], k
