"""Consensus blocks against their definitions: the random geometric graph links exactly the
robots closer than the radius (distances by hand from the round's positions), and a message
carries the bytes of the module's encoding (float64 reals, the upper triangle of a symmetric
matrix, a 2-byte degree where Metropolis weights need it, none in max-c consensus)."""

import numpy as np

from pipeline.fusion.consensus import (
    RandomGeometricTopology,
    max_c_consensus,
    ml_consensus,
)


def test_random_geometric_graph_links_the_pairs_closer_than_the_radius():
    topo = RandomGeometricTopology(7, n_problems=3, radius=0.45, seed=4)
    for t in range(5):
        pos = topo.positions(t)
        want = {(b * 7 + i, b * 7 + j) for b in range(3) for i in range(7)
                for j in range(i + 1, 7) if np.linalg.norm(pos[b, i] - pos[b, j]) < 0.45}
        assert set(map(tuple, topo.edges(t).tolist())) == want


def test_message_bytes_follow_the_encoding():
    edges = np.array([[0, 1], [1, 2], [2, 3]])
    d, K = 3, 2
    P0 = np.broadcast_to(np.eye(d), (4, K, d, d)).copy()
    q0 = np.zeros((4, K, d))
    *_, stats = ml_consensus(P0, q0, edges, rounds=5)
    per_message = 8 * K * (d * (d + 1) // 2 + d) + 2
    assert (stats.rounds, stats.messages) == (5, 5 * 2 * 3)
    assert stats.bytes == stats.messages * per_message
    draws = np.random.default_rng(0).random((4, K))
    _, st = max_c_consensus(draws, edges, c=2, rounds=3)
    assert st.bytes == 3 * 2 * 3 * 8 * K * 2


def test_ransac_count_is_the_smallest_that_reaches_the_success_exactly():
    # (1 − p_in^c)^K <= 1 − success in exact rational arithmetic; 0.7 and 0.91 put the
    # boundary exactly at K = 2 (the float quotient of the logarithms is 2.0000000000000004)
    from fractions import Fraction

    from pipeline.fusion.consensus import ransac_hypotheses

    for p_in, c, success in [("0.7", 1, "0.91"), ("0.9", 1, "0.99"), ("0.5", 2, "0.9375"),
                             ("0.6", 1, "0.99"), ("0.8", 3, "0.999")]:
        bad, miss = 1 - Fraction(p_in) ** c, 1 - Fraction(success)
        want = next(k for k in range(1, 1000) if bad ** k <= miss)
        assert ransac_hypotheses(float(p_in), c, float(success)) == want
