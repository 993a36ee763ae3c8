"""Bounded label flooding: every feature ends with its set's member list or knows the set is
larger than the budget, as a centralized union-find says (Hypothesis)."""

from functools import partial
from unittest.mock import patch

import numpy as np
from consistency_graphs import instances
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import shortest_path

from pipeline.association import AssociationGraph, conflictive_labels
from pipeline.commgraph import comm_edges_for
from pipeline.consistency.engines import evidence_stage
from pipeline.consistency.engines.driver import build_robots
from pipeline.consistency.engines.evidence_stage import run_setlists, run_setlists_batched
from pipeline.transport.simulated import Network

SETTINGS = settings(max_examples=100, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(inst=instances(max_n=7, max_feat=5), budget=st.integers(1, 8))
def test_each_feature_learns_its_set_or_that_it_is_large(inst, budget):
    fpc, edges, links = inst
    robots, _ = build_robots(fpc, links)
    network = Network(len(fpc), comm_edges_for(fpc, links, edges))
    rounds = run_setlists(robots, network, budget)
    graph = AssociationGraph(fpc, links)
    labels, sizes, conflictive = conflictive_labels(graph)
    offsets = np.r_[0, np.cumsum(fpc)]
    members = {}
    for g, lab in enumerate(labels.tolist()):
        members.setdefault(lab, []).append(g)
    linked = np.zeros(offsets[-1], dtype=bool)
    linked[np.r_[offsets[links.cam_i] + links.feat_i, offsets[links.cam_j] + links.feat_j]] = True
    for rb in robots:
        for r in range(rb.m):
            g = rb.gid0 + r
            lab = int(labels[g])
            lst = rb.setlists.ids[rb.setlists.r == r]
            if not linked[g]:
                assert lst.size == 0 and not rb.setlists.large[r]  # not active: no link
                continue
            large = sizes[lab] > budget
            assert rb.setlists.large[r] == large
            # the B + 1 smallest ids of the set, sorted: the whole set when it is small
            assert lst.tolist() == members[lab][:budget + 1]
            assert rb.conflictive[r] == (not large and conflictive[lab])
            row = rb.X.indices[rb.X.indptr[r]:rb.X.indptr[r + 1]]
            assert sorted(row.tolist()) == (members[lab] if rb.conflictive[r] else [])
            assert rb.set_label[r] == (members[lab][0] if rb.conflictive[r] else -1)
            named = not large and not conflictive[lab]
            assert rb.track_label[r] == (members[lab][0] if named else -1)
    # an id moves one link per round: the flood ends within the largest set diameter + 1
    A = graph.adjacency()
    D = shortest_path(A, unweighted=True, directed=False) if A.nnz else np.zeros((1, 1))
    diam = int(D[np.isfinite(D)].max(initial=0))
    assert rounds <= diam + 1
    # memory follows the links: at most B + 1 ids per feature held
    assert all(np.bincount(rb.setlists.r, minlength=rb.m).max(initial=0) <= budget + 1
               for rb in robots)


@SETTINGS
@given(inst=instances(max_n=7, max_feat=5), budget=st.integers(1, 8),
       p_cut=st.sampled_from([0.0, 0.3]), seed=st.integers(0, 2**32 - 1),
       chunk=st.sampled_from([1, 5, 1 << 21]))
def test_the_batched_flood_leaves_every_robot_in_the_per_robot_state(inst, budget, p_cut, seed,
                                                                     chunk):
    fpc, edges, links = inst
    edges = comm_edges_for(fpc, links, edges)
    runs = []
    batched = partial(_patched, chunk)
    for flood in (run_setlists, batched):
        robots, _ = build_robots(fpc, links)
        rng = np.random.default_rng(seed)
        for rb in robots:  # links cut at one end only: the receiver's own rows decide
            rb.link_alive &= rng.random(rb.link_alive.size) >= p_cut
        network = Network(len(fpc), edges)
        rounds = flood(robots, network, budget, None, 3)
        runs.append((robots, network.counters(), rounds))
    (ra, ca, ta), (rb_, cb, tb) = runs
    assert ta == tb and ca == cb
    for a, b in zip(ra, rb_, strict=True):
        for k in ("r", "ids", "new_r", "new_ids", "heard", "large"):
            np.testing.assert_array_equal(getattr(a.setlists, k), getattr(b.setlists, k), k)
        for k in ("conflictive", "set_label", "track_label", "active"):
            np.testing.assert_array_equal(getattr(a, k), getattr(b, k), k)
        assert (a.X != b.X).nnz == 0
        assert a.t_stop == b.t_stop and a.stopped == b.stopped
        assert a.peak_memory_bytes == b.peak_memory_bytes


def _patched(chunk, *args):
    """The batched flood with its merge cut in pieces of ``chunk`` entries."""
    with patch.object(evidence_stage, "CHUNK_ENTRIES", chunk):
        return run_setlists_batched(*args)
