"""The fusion's memory follows the robots that observe each track, not the whole team: its
robot × robot work per track is on the track's observers (the flood and the decisions) or
bounded chunk by chunk (the local estimates)."""

import tracemalloc

import numpy as np

from pipeline.fusion.flooding import exact_dynamic_voting
from pipeline.fusion.landmarks import CHUNK_ENTRIES, _track_chunks
from pipeline.fusion.voting import gate_threshold


def _sparse_tracks(n: int, B: int, K: int):
    """``B`` tracks on a path of ``n`` robots, each observed by 3 consecutive robots."""
    rng = np.random.default_rng(0)
    comm = np.stack([np.arange(n - 1), np.arange(1, n)], 1)
    observes = np.zeros((B, n), dtype=bool)
    first = rng.integers(0, n - 3, B)
    for b, f in enumerate(first):
        observes[b, f:f + 3] = True
    ne, el = [], []
    for k, (i, j) in enumerate(comm):
        b = np.flatnonzero(observes[:, i] & observes[:, j])
        ne.append(np.stack([b * n + i, b * n + j], 1))
        el.append(np.full(len(b), k))
    ne, el = np.concatenate(ne).astype(np.int64), np.concatenate(el).astype(np.int64)
    x = rng.normal(0, 1, (B, 1, 3)) + rng.normal(0, 0.05, (B, n, 3))
    cov = np.broadcast_to(0.01 * np.eye(3), (B, n, 3, 3)).copy()
    draws = 1.0 - rng.random((B, n, K))
    return comm, observes, ne, el, x, cov, draws


def test_exact_voting_holds_no_robot_by_robot_table_per_track():
    # 800 robots, 16 tracks of 3 observers each: a (B, n, n) bool table alone is 10.2 MB,
    # the per-(track, robot) inputs (x, cov, draws) 1.8 MB
    n, B, K = 800, 16, 6
    comm, observes, ne, el, x, cov, draws = _sparse_tracks(n, B, K)
    tracemalloc.start()
    try:
        res = exact_dynamic_voting(x, cov, observes, observes, ne, el, len(comm), K=K, c=1,
                                   thr=gate_threshold(3, 0.99, "squared"), draws=draws)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert res.valid[observes].all()
    # a few copies of the per-(track, robot) inputs, less than one byte per (track, robot,
    # robot)
    inputs = x.nbytes + cov.nbytes + draws.nbytes
    assert peak < 4 * inputs
    assert peak < B * n * n


def test_track_chunks_cover_the_tracks_in_order_within_the_cap():
    n, B = 600, 40
    _, observes, ne, _, _, _, _ = _sparse_tracks(n, B, 1)
    chunks = _track_chunks(observes, ne)
    assert [s.start for s in chunks] == [0] + [s.stop for s in chunks[:-1]]
    assert chunks[-1].stop == B
    # each chunk works on at most CHUNK_ENTRIES robot × robot entries (here n² + 2 E_b n +
    # 64 k_b n per track), so more tracks make more chunks, not larger ones
    per_track = n * n + 2 * 2 * n + 64 * 3 * n
    assert all(s.stop - s.start <= max(1, CHUNK_ENTRIES // per_track) for s in chunks)
    assert len(chunks) >= B * per_track // CHUNK_ENTRIES


def _ring_of_six(P=40, seed=5):
    """6 cameras on a ring observing ``P`` points (70 % each), some keypoints planted off:
    per camera its views, keypoints and track names (point id + 1000)."""
    from data_synth.formations import look_at

    rng = np.random.default_rng(seed)
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    pts = rng.uniform([-1, -1, 4], [1, 1, 7], (P, 3))
    cams = []
    for v in range(6):
        R, t = look_at([0.6 * v - 1.5, 0.1 * v, 0.0], [0.0, 0.0, 5.5], up=(0.0, 1.0, 0.0))
        seen = np.flatnonzero(rng.random(P) < 0.7)
        p = (K @ (pts[seen] @ R.T + t).T).T
        uv = p[:, :2] / p[:, 2:] + rng.normal(0, 0.3, (len(seen), 2))
        bad = rng.random(len(seen)) < 0.1
        uv[bad] += rng.uniform(15, 40, (int(bad.sum()), 2))
        cams.append((K, R, t, uv.astype(np.float32), seen + 1000))
    return cams


def _run_robots(cams, n, consensus="exact"):
    """The 6 robots' fusion, round by round, in a team of ``n`` (robots 6.. are idle)."""
    from types import SimpleNamespace

    from pipeline.fusion.robot import FusionOptions, FusionRobot

    edges = np.array([(i, i + 1) for i in range(5)] + [(0, 5)])
    robots = [FusionRobot(i, n, edges, names, kp, K, R, t, FusionOptions(consensus=consensus))
              for i, (K, R, t, kp, names) in enumerate(cams)]
    for _ in range(3 * n + 200):
        if all(r.done for r in robots):
            break
        sent = [(r.i, dst, kind, payload) for r in robots for dst, kind, payload in r.messages()]
        for r in robots:
            r.receive([SimpleNamespace(src=s, kind=k, payload=p)
                       for s, d, k, p in sent if d == r.i])
    assert all(r.done for r in robots)
    return robots


def _same_decisions_and_peak(n, *mode):
    """The 6 ring robots' fusion alone and in a team of ``n``: the same outliers (the team
    size changes no decision), and the traced peak of the team run with its own-track count."""
    cams = _ring_of_six()
    small = _run_robots(cams, 6, *mode)
    tracemalloc.start()
    try:
        big = _run_robots(cams, n, *mode)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert any(len(r.outlier_feats) for r in small)
    for a, b in zip(small, big, strict=True):
        np.testing.assert_array_equal(a.outlier_feats, b.outlier_feats)
    return peak, sum(r.B for r in big)


def test_a_robot_s_fusion_follows_its_neighbours_and_tracks_not_the_team_squared():
    # 6 robots on a ring in a team of 1000: each robot's setup tables, flood and components
    # are on itself and its neighbours (and the robots of its tracks), so the 6 robots' fusion
    # peaks well below one byte per (own track, robot, robot) of the team (before: several)
    n = 1000
    peak, tracks = _same_decisions_and_peak(n)
    assert peak < tracks * n * n / 2


def test_a_robot_s_metropolis_consensus_holds_its_neighbours_rows_only():
    # the Metropolis mode keeps what each neighbour sent (max-c sets, P, q, v, degrees, stop
    # counters) per own track and neighbour: in a team of 300 the 6 robots peak below one
    # 3 x 3 float64 matrix per (own track, team robot) (before: about 7 of them)
    n = 300
    peak, tracks = _same_decisions_and_peak(n, "metropolis")
    assert peak < tracks * n * 72
