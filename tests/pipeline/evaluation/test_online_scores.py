"""pipeline.evaluation.online: the scoped pairwise score equals the full one on a full scope."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from data_synth.motion import render_motion
from pipeline.evaluation.metrics import PairwiseTruth, true_pairs_all
from pipeline.evaluation.online import ScopedTruth, scope_pairs
from pipeline.matching.features import extract_all
from pipeline.types import Links


def test_full_scope_equals_the_pairwise_score():
    s = render_motion("complete", seed=0, steps=2, size=(160, 120), n_robots=2)
    feats = extract_all(s.flat.views, "sift", 150)
    m = np.array([len(f) for f in feats])
    robot, step = np.tile(np.arange(2), 2), np.repeat(np.arange(2), 2)
    scope = scope_pairs(robot, step, s.comm_edges, horizon=2)
    assert len(scope) == 6                       # every pair of the 4 frames
    st = ScopedTruth(s.flat, feats, scope)
    full = PairwiseTruth(true_pairs_all(s.flat, feats), int(m.sum()))
    rng = np.random.default_rng(0)
    for _ in range(3):                           # random associations, cross-frame links
        ci = rng.integers(0, 3, 40)
        cj = ci + 1
        fi = rng.integers(0, m[ci])
        fj = rng.integers(0, m[cj])
        key = np.unique(np.stack([ci, fi, cj], 1), axis=0, return_index=True)[1]
        key = key[np.unique(np.stack([ci[key], fj[key], cj[key]], 1), axis=0,
                            return_index=True)[1]]
        links = Links(ci[key], fi[key], cj[key], fj[key])
        assert st.scores(links) == full.scores(m, links)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 4), st.integers(1, 5), st.integers(1, 3), st.integers(0, 10_000))
def test_the_scope_is_every_pair_a_step_matched(n, steps, window, seed):
    """With a switching topology the scope is the union of the pairs each step matched
    (pipeline.matching.pairs.step_pairs on the edges up at that step); it was built from the
    static graph, counting pairs never matchable in the recall."""
    from pipeline.matching.pairs import step_pairs

    rng = np.random.default_rng(seed)
    all_edges = [(i, j) for i in range(n) for j in range(i + 1, n)]
    step_edges = [np.array([e for e in all_edges if rng.random() < 0.5], np.int64).reshape(-1, 2)
                  for _ in range(steps)]
    frames = np.arange(n * steps)
    robot, step = frames % n, frames // n
    want = set()
    for t in range(steps):
        so_far = step <= t
        want |= {tuple(p) for p in step_pairs(robot[so_far], step[so_far], t, window,
                                               step_edges[t]).tolist()}
    got = scope_pairs(robot, step, np.array(all_edges).reshape(-1, 2), window,
                      step_edges=step_edges)
    assert {tuple(p) for p in got.tolist()} == want
