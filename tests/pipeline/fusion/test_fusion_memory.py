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
