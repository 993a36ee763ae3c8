"""Exact dynamic voting by flooding: the vectorized simulator equals the robots one by one, the
flood closes at eccentricity + 1, and the decision is the fixed point of the gate map."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import shortest_path

from pipeline.fusion.decision import decide
from pipeline.fusion.flood_robot import FloodRobot
from pipeline.fusion.flooding import flood, run_robots, run_robots_on
from pipeline.fusion.protocol import CountingExchange, LockstepExchange, to_wire
from pipeline.fusion.voting import gate_threshold
from pipeline.transport.simulated import Network, NetworkOptions


def _instance(seed, n, B, K, wire="float32"):
    rng = np.random.default_rng(seed)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    comm = np.array([p for p in pairs if rng.random() < 0.6] or [pairs[0]], dtype=np.int64)
    observes = rng.random((B, n)) < 0.75
    estimated = observes & (rng.random((B, n)) < 0.85)
    ne, el = [], []
    for k, (i, j) in enumerate(comm):
        b = np.flatnonzero(observes[:, i] & observes[:, j])
        ne.append(np.stack([b * n + i, b * n + j], 1))
        el.append(np.full(len(b), k))
    ne = np.concatenate(ne).astype(np.int64)
    el = np.concatenate(el).astype(np.int64)
    centre = rng.normal(0, 1, (B, 1, 3))
    x = centre + rng.normal(0, 0.05, (B, n, 3))
    out = rng.random((B, n)) < 0.3
    x[out] += rng.normal(0, 2, (out.sum(), 3))
    A = rng.normal(0, 1, (B, n, 3, 3))
    info = A @ np.swapaxes(A, -1, -2) * 50 + 10 * np.eye(3)
    draws = np.where(estimated[..., None], 1.0 - rng.random((B, n, K)), -np.inf)
    return comm, observes, estimated, ne, el, to_wire(x, wire), to_wire(info, wire), draws


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(2, 6), B=st.integers(1, 4),
       K=st.integers(1, 4), c=st.integers(1, 2), wire=st.sampled_from(["float32", "float64"]))
def test_vectorized_flood_equals_the_robots_one_by_one(seed, n, B, K, c, wire):
    comm, observes, est, ne, el, x, info, draws = _instance(seed, n, B, K, wire)
    thr = gate_threshold(3, 0.99, "squared")
    run = flood(observes, ne, el, len(comm), estimated=est, K=K, d=3, wire=wire)
    rows = np.flatnonzero(observes.reshape(-1))
    tb = rows // n
    dec = decide(run.known[rows], est[tb], draws[tb], x[tb], info[tb], c=c, thr=thr)

    nbr = np.zeros((B * n, n), dtype=bool)
    nbr[ne[:, 0], ne[:, 1] % n] = nbr[ne[:, 1], ne[:, 0] % n] = True
    robots = [FloodRobot(i, n, {b: dict(neighbours=nbr[b * n + i], estimated=est[b, i],
                                        draws=draws[b, i], x=x[b, i], info=info[b, i])
                                for b in np.flatnonzero(observes[:, i])},
                         K=K, d=3, wire=wire, c=c, thr=thr) for i in range(n)]
    rounds, sizes = run_robots(robots)
    assert rounds == run.rounds == len(run.sizes)
    for t in range(rounds):
        want = {}
        for k, (i, j) in enumerate(comm):
            for s_, d_, v in ((i, j, run.sizes[t][2 * k]), (j, i, run.sizes[t][2 * k + 1])):
                if v:
                    want[(int(s_), int(d_))] = int(v)
        assert sizes[t] == want
    for r, node in enumerate(rows):
        b, i = divmod(int(node), n)
        one = robots[i].decisions[b]
        assert robots[i].tracks[b].decided_round == run.decided_round[node]
        np.testing.assert_array_equal(robots[i].tracks[b].known_at_decision, run.known[node])
        assert one.winner == dec.winner[r] and one.valid == dec.valid[r]
        np.testing.assert_array_equal(one.counts, dec.counts[r])
        np.testing.assert_array_equal(one.yes, dec.yes[r])
        np.testing.assert_array_equal(one.members, dec.members[r])
        np.testing.assert_array_equal(one.theta, dec.theta[r])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(2, 7))
def test_each_robot_holds_its_component_and_decides_after_its_eccentricity(seed, n):
    comm, observes, est, ne, el, x, info, draws = _instance(seed, n, 3, 2)
    run = flood(observes, ne, el, len(comm), estimated=est, K=2, d=3, wire="float32")
    B = observes.shape[0]
    adj = np.zeros((B * n, B * n))
    adj[ne[:, 0], ne[:, 1]] = adj[ne[:, 1], ne[:, 0]] = 1
    dist = shortest_path(adj, unweighted=True)
    assert run.settled
    for node in np.flatnonzero(observes.reshape(-1)):
        b = node // n
        comp = np.isfinite(dist[node, b * n:(b + 1) * n])
        np.testing.assert_array_equal(run.known[node], comp)
        ecc = int(dist[node, b * n:(b + 1) * n][comp].max())
        assert run.decided_round[node] == ecc
    # a robot sends its last message the round after it decided (unless every neighbour
    # stopped before): Diam + 1 rounds at most
    decided = run.decided_round[observes.reshape(-1)]
    if len(ne):
        assert decided.max() <= run.rounds <= decided.max() + 1
    else:
        assert run.rounds == 0


def test_decision_is_the_ml_of_a_fixed_point_of_the_gate():
    rng = np.random.default_rng(0)
    n = 7
    x = rng.normal(0, 0.01, (1, n, 3))
    x[0, [2, 5]] += [5.0, 0, 0]                                     # two outliers
    info = np.broadcast_to(np.eye(3) * 1e4, (1, n, 3, 3)).copy()
    draws = np.array([[[0.1, 0.2], [0.9, 0.3], [0.5, 0.95], [0.2, 0.1], [0.3, 0.4],
                       [0.4, 0.5], [0.6, 0.7]]])                     # h0: robot 1, h1: robot 2
    thr = gate_threshold(3, 0.99, "squared")
    dec = decide(np.ones((1, n), bool), np.ones((1, n), bool), draws, x, info, c=1, thr=thr)
    inl = np.ones(n, bool)
    inl[[2, 5]] = False
    np.testing.assert_array_equal(dec.yes[0, 0], inl)
    np.testing.assert_array_equal(dec.yes[0, 1], ~inl)
    assert dec.counts[0].tolist() == [5, 2] and dec.winner[0] == 0
    np.testing.assert_allclose(dec.theta[0], x[0, inl].mean(0), atol=1e-12)
    # votes are counts: a tie goes to the lowest hypothesis index, whatever the values
    x2 = x.copy()
    x2[0, [2, 5, 6]] = x[0, [2, 5]].mean(0) + rng.normal(0, 0.01, (3, 3))
    x2[0, 0] += [0, 5.0, 0]
    dec2 = decide(np.ones((1, n), bool), np.ones((1, n), bool), draws, x2, info, c=1, thr=thr)
    assert dec2.counts[0].tolist() == [3, 3] and dec2.winner[0] == 0
    dec3 = decide(np.ones((1, n), bool), np.ones((1, n), bool), draws[:, :, ::-1], x2, info,
                  c=1, thr=thr)
    assert dec3.counts[0].tolist() == [3, 3] and dec3.winner[0] == 0
    assert not dec3.yes[0, 0, 1] and dec3.yes[0, 1, 1]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(2, 8), K=st.integers(1, 4))
def test_decided_sets_are_fixed_points_of_the_gate_and_votes_are_counts(seed, n, K):
    comm, observes, est, ne, el, x, info, draws = _instance(seed, n, 2, K, "float64")
    thr = gate_threshold(3, 0.99, "squared")
    known = observes
    dec = decide(known, est, draws, x, info, c=1, thr=thr)
    obs = known & est
    for r in range(len(known)):
        for h in range(K):
            S = dec.yes[r, h]
            assert dec.counts[r, h] == S.sum() and not (S & ~obs[r]).any()
            if dec.cycles[r, h] or not S.any():
                continue
            Pi = info[r, S].sum(0)
            theta = np.linalg.solve(Pi, (info[r, S] @ x[r, S][..., None]).sum(0)[:, 0])
            res = x[r] - theta
            m2 = np.einsum("ni,nij,nj->n", res, info[r], res)
            # a fixed point of F up to round-off at the gate's edge
            clear = np.abs(m2 - thr) > 1e-6 * thr
            np.testing.assert_array_equal(S[clear], (obs[r] & (m2 <= thr))[clear])
        best = dec.counts[r].max()
        assert dec.winner[r] == np.flatnonzero(dec.counts[r] == best)[0]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(2, 6), B=st.integers(1, 6),
       K=st.integers(1, 4))
def test_exact_dynamic_voting_decides_every_robot_as_decide_does(seed, n, B, K):
    # the stage decides each distinct (track, entries held) once and hands the result to
    # every robot holding those entries: it must equal every robot deciding for itself
    from pipeline.fusion.flooding import exact_dynamic_voting
    from pipeline.fusion.voting import information_matrix

    comm, observes, est, ne, el, x, info, draws = _instance(seed, n, B, K, "float64")
    cov = np.linalg.inv(info)
    thr = gate_threshold(3, 0.99, "squared")
    res = exact_dynamic_voting(x, cov, est, observes, ne, el, len(comm), K=K, c=1, thr=thr,
                               draws=np.where(est[..., None], draws, 0.5), wire="float32")
    infow = to_wire(np.where(est[..., None, None], information_matrix(
        np.where(est[..., None, None], cov, np.eye(3))), 0.0), "float32")
    xw = to_wire(np.where(est[..., None], x, 0.0), "float32")
    run = flood(observes, ne, el, len(comm), estimated=est, K=K, d=3, wire="float32")
    rows = np.flatnonzero(observes.reshape(-1))
    tb, own = rows // n, rows % n
    dec = decide(run.known[rows], est[tb], draws[tb], xw[tb], infow[tb], c=1, thr=thr)
    np.testing.assert_array_equal(res.theta.reshape(-1, 3)[rows], dec.theta)
    np.testing.assert_array_equal(res.valid.reshape(-1)[rows], dec.valid)
    np.testing.assert_array_equal(res.winner.reshape(-1)[rows], dec.winner)
    np.testing.assert_array_equal(res.votes.reshape(-1, K)[rows],
                                  dec.counts / np.maximum(dec.size, 1)[:, None])
    np.testing.assert_array_equal(res.inlier.reshape(-1)[rows],
                                  dec.yes[np.arange(len(rows)), dec.winner, own] & dec.valid)


def test_robot_step_returns_a_new_state_and_leaves_the_old_one():
    from pipeline.fusion.flood_robot import robot_step

    nb = np.array([False, True, False])
    r = FloodRobot(0, 3, {7: dict(neighbours=nb, estimated=True, draws=[0.5], x=np.zeros(3),
                                  info=np.eye(3))}, K=1, d=3, wire="float32", c=1, thr=11.3)
    new, out = robot_step(r, [])
    assert r.round == 0 and new.round == 1
    assert [(m.src, m.dst, list(m.tracks)) for m in out] == [(0, 1, [7])]
    last, entries = out[0].tracks[7]
    assert not last and entries.robot.tolist() == [0]


def _robots(n, observes, est, ne, x, info, draws, K, wire="float32", c=1):
    B = observes.shape[0]
    thr = gate_threshold(3, 0.99, "squared")
    nbr = np.zeros((B * n, n), dtype=bool)
    nbr[ne[:, 0], ne[:, 1] % n] = nbr[ne[:, 1], ne[:, 0] % n] = True
    return [FloodRobot(i, n, {int(b): dict(neighbours=nbr[b * n + i], estimated=est[b, i],
                                           draws=draws[b, i], x=x[b, i], info=info[b, i])
                              for b in np.flatnonzero(observes[:, i])},
                       K=K, d=3, wire=wire, c=c, thr=thr) for i in range(n)]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(2, 6), B=st.integers(1, 3))
def test_robots_over_a_lossless_exchange_are_the_vectorized_flood(seed, n, B):
    comm, observes, est, ne, el, x, info, draws = _instance(seed, n, B, 2)
    run = flood(observes, ne, el, len(comm), estimated=est, K=2, d=3, wire="float32")
    robots = _robots(n, observes, est, ne, x, info, draws, 2)
    ex = CountingExchange(len(comm))
    rounds, sizes = run_robots_on(robots, comm, ex)
    assert rounds == run.rounds and ex.rounds == rounds
    for a, b in zip(sizes, run.sizes, strict=True):
        np.testing.assert_array_equal(a, b)
    for node in np.flatnonzero(observes.reshape(-1)):
        b, i = divmod(int(node), n)
        np.testing.assert_array_equal(robots[i].tracks[b].known_at_decision, run.known[node])


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(3, 7), B=st.integers(1, 3),
       dead=st.integers(0, 6), when=st.floats(0, 1), drop=st.sampled_from([0.0, 0.3]),
       fault=st.sampled_from(["crash", "link"]), delay=st.sampled_from([0, 2]))
def test_a_crash_during_the_flood_leaves_every_survivor_of_a_track_with_one_decision(
        seed, n, B, dead, when, drop, fault, delay):
    """Every surviving observer of a track decides on the survivors of its connected remainder
    (the same set, so the same winner, inliers and point); the crashed robot is in no decision.
    The crash falls anywhere in the fault-free run's network rounds (``when``); ``link``: no
    robot crashes but one comm link fails for good (both ends live, declared lost), possibly
    with messages in flight on it (``delay``)."""
    from scipy.sparse.csgraph import connected_components

    comm, observes, est, ne, el, x, info, draws = _instance(seed, n, B, 2)
    free = Network(n, comm, NetworkOptions(drop_probability=drop, delay_rounds=delay,
                                           seed=seed))
    run_robots_on(_robots(n, observes, est, ne, x, info, draws, 2), comm,
                  LockstepExchange(free, comm))
    at = int(when * free.round)
    if fault == "crash":
        dead = dead % n
        opts = NetworkOptions(crash_at={dead: at}, drop_probability=drop, delay_rounds=delay,
                              seed=seed)
    else:
        broken = comm[dead % len(comm)]
        rest = comm[(comm != broken).any(1)]
        dead = -1
        opts = NetworkOptions(topology=lambda t: comm if t < at else rest,
                              drop_probability=drop, delay_rounds=delay, seed=seed)
    net = Network(n, comm, opts)
    ex = LockstepExchange(net, comm)
    robots = _robots(n, observes, est, ne, x, info, draws, 2)
    run_robots_on(robots, comm, ex)
    crashed = ex.crashed
    assert crashed <= {dead}
    up = ex.link_up
    for b in range(B):
        alive_edges = [(i, j) for k, (i, j) in enumerate(comm) if up[k]
                       and observes[b, i] and observes[b, j]
                       and i not in crashed and j not in crashed]
        adj = np.zeros((n, n))
        for i, j in alive_edges:
            adj[i, j] = adj[j, i] = 1
        _, lab = connected_components(adj, directed=False)
        survivors = [i for i in range(n) if observes[b, i] and i not in crashed]
        for i in survivors:
            st_ = robots[i].tracks[b]
            assert st_.done and not st_.forced
            want = np.array([k in survivors and lab[k] == lab[i] for k in range(n)])
            np.testing.assert_array_equal(st_.known_at_decision, want)
            ref = robots[min(k for k in survivors if lab[k] == lab[i])].decisions[b]
            one = robots[i].decisions[b]
            assert one.winner == ref.winner and one.valid == ref.valid
            np.testing.assert_array_equal(one.yes, ref.yes)
            np.testing.assert_array_equal(one.theta, ref.theta)
            if crashed:
                assert not one.yes[:, dead].any()
