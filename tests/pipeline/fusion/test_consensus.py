import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.fusion.consensus import (
    FixedTopology,
    RandomGeometricTopology,
    SwitchingTopology,
    average_consensus,
    graph_diameter,
    hypothesis_members,
    information_form,
    max_c_consensus,
    metropolis_weights,
    ml_consensus,
    ransac_hypotheses,
    ransac_success,
)


@st.composite
def connected_graphs(draw, max_nodes=12):
    """A random connected graph: a random tree plus random extra edges."""
    n = draw(st.integers(2, max_nodes))
    parents = [draw(st.integers(0, k - 1)) for k in range(1, n)]
    edges = {(p, k) for k, p in zip(range(1, n), parents, strict=True)}
    extra = draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=2 * n))
    edges |= {(min(a, b), max(a, b)) for a, b in extra if a != b}
    return n, np.array(sorted(edges), dtype=np.int64)


def ring(n):
    return np.array([(k, (k + 1) % n) for k in range(n)])


@given(connected_graphs())
def test_metropolis_doubly_stochastic_with_graph_sparsity(g):
    n, e = g
    A = metropolis_weights(e, n).toarray()
    assert np.allclose(A, A.T)
    assert np.allclose(A.sum(0), 1) and np.allclose(A.sum(1), 1)
    assert (np.diag(A) > 0).all()
    # row i only uses i and its neighbours: the messages it received
    allowed = np.eye(n, dtype=bool)
    allowed[e[:, 0], e[:, 1]] = allowed[e[:, 1], e[:, 0]] = True
    assert (A[~allowed] == 0).all()


def test_metropolis_hand_computed_path():
    A = metropolis_weights([[0, 1], [1, 2]], 3).toarray()
    third = 1 / 3
    assert np.allclose(A, [[1 - third, third, 0], [third, third, third], [0, third, 1 - third]])


def test_average_consensus_fixed_graph_converges_to_mean():
    rng = np.random.default_rng(0)
    x0 = rng.normal(size=(8, 3))
    x, stats = average_consensus(x0, ring(8), rounds=300)
    assert np.allclose(x, x0.mean(0), atol=1e-9)
    assert stats.rounds == 300
    assert stats.messages == 300 * 2 * 8


def test_average_consensus_switching_graph_converges_to_mean():
    # every single round is disconnected; the union of two consecutive rounds is a ring
    n = 8
    even = np.array([(k, k + 1) for k in range(0, n, 2)])
    odd = np.array([(k, (k + 1) % n) for k in range(1, n, 2)])
    rng = np.random.default_rng(1)
    x0 = rng.normal(size=(n, 2))
    x, stats = average_consensus(x0, SwitchingTopology([even, odd], n), rounds=400)
    assert np.allclose(x, x0.mean(0), atol=1e-9)
    assert stats.messages == 400 * 2 * (n // 2)
    # random geometric graphs redrawn every round also reach the mean
    x, _ = average_consensus(x0, RandomGeometricTopology(n, 1, radius=0.5, seed=3), rounds=300)
    assert np.allclose(x, x0.mean(0), atol=1e-8)


def test_random_geometric_topology_is_a_function_of_the_round():
    topo = RandomGeometricTopology(6, 4, radius=0.5, seed=7)
    e3 = topo.edges(3).copy()
    topo.edges(1)
    assert np.array_equal(topo.edges(3), e3)
    # problems never share an edge
    assert (e3[:, 0] // 6 == e3[:, 1] // 6).all()


def random_covariances(rng, n, d):
    Q = np.linalg.qr(rng.normal(size=(n, d, d)))[0]
    ev = rng.uniform(0.1, 2.0, size=(n, d))
    return Q @ (ev[..., None] * np.swapaxes(Q, -1, -2))


def test_distributed_ml_equals_central_eq1():
    rng = np.random.default_rng(2)
    n, d = 9, 3
    x = rng.normal(size=(n, d))
    cov = random_covariances(rng, n, d)
    info = np.linalg.inv(cov)
    central = np.linalg.solve(info.sum(0), (info @ x[..., None]).sum(0)[:, 0])  # eq. (1)
    P0, q0 = information_form(x, cov)
    edges = np.array([(k, k + 1) for k in range(n - 1)] + [(0, 4), (2, 7)])
    theta, P, _, ok, _ = ml_consensus(P0, q0, edges, rounds=400)
    assert ok.all()
    assert np.allclose(theta, central, atol=1e-9)
    assert np.allclose(P, info.mean(0), atol=1e-9)  # eq. (3)


def test_partial_ml_prop_3_1():
    rng = np.random.default_rng(3)
    n, d = 7, 2
    x = rng.normal(size=(n, d))
    cov = random_covariances(rng, n, d)
    subset = np.array([1, 0, 0, 1, 0, 1, 0], dtype=bool)
    info = np.linalg.inv(cov[subset])
    central = np.linalg.solve(info.sum(0), (info @ x[subset][..., None]).sum(0)[:, 0])  # eq. (4)
    P0, q0 = information_form(x, cov, subset)  # eq. (5)
    theta, *_ = ml_consensus(P0, q0, ring(n), rounds=400)
    assert np.allclose(theta, central, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(connected_graphs(), st.integers(1, 4), st.integers(1, 3), st.integers(0, 2**32 - 1))
def test_max_c_selects_c_largest_within_diameter(g, c, K, seed):
    n, e = g
    rng = np.random.default_rng(seed)
    draws = rng.random((n, K)) + 1e-9
    diam = graph_diameter(e, n)
    sets, stats = max_c_consensus(draws, e, c, rounds=diam)
    top = -np.sort(-draws, axis=0)[:c].T  # (K, min(c, n))
    m = min(c, n)
    assert np.array_equal(sets[:, :, :m], np.broadcast_to(top, (n, K, m)))
    assert np.isneginf(sets[:, :, m:]).all()
    members = hypothesis_members(draws, sets)
    assert (members.sum(0) == m).all()  # eq. (7): exactly the c robots of largest draw
    assert stats.rounds == diam and stats.messages == 2 * len(e) * diam


def test_max_c_path_needs_the_diameter():
    n = 6
    path = np.array([(k, k + 1) for k in range(n - 1)])
    draws = np.arange(1, n + 1, dtype=float)[:, None]  # largest at the far end
    sets, _ = max_c_consensus(draws, path, 2, rounds=n - 2)
    assert not np.all(sets[0, 0] == [6, 5])
    sets, _ = max_c_consensus(draws, path, 2, rounds=n - 1)
    assert np.all(sets[:, 0] == [6, 5])


def test_ransac_counts_of_sec_v():
    assert ransac_hypotheses(0.6, 1, 0.99) == 6  # Fig. 2-3 example
    assert ransac_hypotheses(0.8, 1, 0.99) == 3  # Monte Carlo
    assert ransac_success(0.8, 1, 3) >= 0.99 > ransac_success(0.8, 1, 2)
    with pytest.raises(InputError, match="p_in"):
        ransac_hypotheses(0.0, 1)


def test_bad_edges_name_the_problem():
    with pytest.raises(InputError, match="self-loop"):
        FixedTopology([[0, 0]], 3)
    with pytest.raises(InputError, match="nodes 0..2"):
        FixedTopology([[0, 5]], 3)


def test_fixed_topology_weights_are_sparse_matrix():
    A = FixedTopology(ring(5), 5).weights(0)
    assert sp.issparse(A) and A.nnz == 5 + 10


def test_closed_form_3x3_eigenvalues_match_lapack():
    from pipeline.fusion.consensus import extreme_eigenvalues_sym3

    rng = np.random.default_rng(1)
    A = rng.normal(size=(2000, 3, 3))
    A = A + np.swapaxes(A, 1, 2)
    B = rng.normal(size=(500, 3, 2))
    singular = B @ np.swapaxes(B, 1, 2)  # rank 2: smallest eigenvalue 0
    for M in (A, 1e6 * singular, np.broadcast_to(2.0 * np.eye(3), (3, 3, 3)), np.zeros((2, 3, 3))):
        lo, hi = extreme_eigenvalues_sym3(M)
        ev = np.linalg.eigvalsh(M)
        scale = np.abs(ev).max(-1) + 1e-300
        assert np.all(np.abs(lo - ev[:, 0]) <= 1e-12 * scale)
        assert np.all(np.abs(hi - ev[:, -1]) <= 1e-12 * scale)


def test_consensus_runs_on_a_transport_graph():
    """A transport's links per round are the consensus graph G(t) (same as its edges)."""
    from pipeline.transport.simulated import Network, NetworkOptions, recurrent_topology

    n, edges = 6, ring(6)
    x0 = np.arange(n, dtype=float)
    on_net, _ = average_consensus(x0, Network(n, edges), 30)
    on_edges, _ = average_consensus(x0, edges, 30)
    np.testing.assert_array_equal(on_net, on_edges)
    topo = recurrent_topology(edges, p_up=0.5, window=3, seed=2)
    switching, stats = average_consensus(x0, Network(n, edges, NetworkOptions(topology=topo)), 200)
    assert stats.messages == sum(2 * len(topo(t)) for t in range(200))
    np.testing.assert_allclose(switching, x0.mean(), atol=1e-6)



@pytest.mark.parametrize("edges, needle", [
    ([[0, 1], [1, 5]], r"edge \(1, 5\) names an unknown node; node ids are 0\.\.2"),
    ([[0, 1], [-1, 2]], r"edge \(-1, 2\) names an unknown node"),
    ([[0, 1], [1, 0]], r"edge \(0, 1\) is listed more than once"),  # was weighed as degree 2
    ([[0, 0], [1, 2]], r"edge \(0, 0\) is a self-edge"),
])
def test_metropolis_weights_and_the_diameter_name_a_bad_edge(edges, needle):
    # numpy's broadcast / bincount ValueErrors, scipy's 'index 5 exceeds matrix dimension',
    # or the weights of a doubled degree
    with pytest.raises(InputError, match=needle):
        metropolis_weights(edges, 3)
    with pytest.raises(InputError, match=needle):
        graph_diameter(edges, 3)
    with pytest.raises(InputError, match="graph of 0 nodes"):
        graph_diameter([], 0)


def test_ransac_counts_refuse_what_is_not_a_count():
    # ransac_success(0.6, 1, -3) returned -14.6 as a probability; c = 1.5 drew 8 hypotheses
    from pipeline.fusion.consensus import ransac_success

    with pytest.raises(InputError, match=r"K \(hypotheses\) must be a whole number >= 0, got -3"):
        ransac_success(0.6, 1, -3)
    with pytest.raises(InputError, match="p_in must be in"):
        ransac_success(float("nan"), 1, 3)
    with pytest.raises(InputError, match=r"c \(points\) must be a whole number >= 1, got 1.5"):
        ransac_hypotheses(0.6, 1.5)
    assert ransac_success(0.6, 1, 6) == pytest.approx(1 - 0.4 ** 6, abs=1e-12)


def test_consensus_rounds_that_are_not_a_count_are_named():
    # rounds=-1 ran no round and returned the initial values as the consensus; 2.7 ran 2
    from pipeline.fusion.consensus import max_c_consensus, ml_consensus

    topo = FixedTopology([[0, 1], [1, 2]], 3)
    for rounds in (-1, 2.7):
        with pytest.raises(InputError, match=f"rounds must be a whole number >= 0, got {rounds}"):
            average_consensus(np.array([1.0, 2.0, 3.0]), topo, rounds)
        with pytest.raises(InputError, match="rounds must be a whole number"):
            ml_consensus(np.tile(np.eye(2), (3, 1, 1)), np.ones((3, 2)), topo, rounds)
        with pytest.raises(InputError, match="rounds must be a whole number"):
            max_c_consensus(np.ones((3, 2)), topo, 1, rounds)
