"""The simulator's matching of an online step (pipeline.runs.transports.sim.online_match)."""

import numpy as np


def test_online_colmap_matching_runs_on_one_thread(monkeypatch):
    """COLMAP's verification on several threads gave a pair other inliers from run to run
    (121 on one run of run-images --sequence, none on the next), so the simulator's links
    differed from run to run and from the robot processes', which verify each pair on one
    thread: the simulator now verifies on one thread too."""
    import pipeline.matching.pairs as pairs
    from data_synth.motion import render_motion
    from pipeline.runs.transports import sim

    seen = []

    def spy(edges, features, *a, threads=-1):
        seen.append(threads)
        return [pairs.PairMatches(int(i), int(j), np.zeros((0, 2), np.int64), np.zeros(0),
                                  np.zeros(0), 0, "") for i, j in edges]

    monkeypatch.setattr(pairs, "_colmap_matches", spy)
    seq = render_motion("ring", 0, 2, (96, 72), 2, window=2)
    views = seq.flat.views
    store: dict = {}
    for t in range(2):
        sim.online_match(views, t, 2, 2, seq.step_edges[t], store, features="sift",
                         max_features=100, merge_radius=0.5, feature_options={},
                         match_options={"matcher": "colmap", "threshold_px": None})
    assert seen == [1, 1]
