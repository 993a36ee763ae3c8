"""data_synth.motion: a formation driving along the facade, with the ground truth of a render."""

import numpy as np
import pytest

import data_synth
from data_synth.ground_truth import true_pairs
from data_synth.motion import render_motion
from pipeline.errors import InputError
from pipeline.matching.features import extract


def test_poses_follow_the_path_and_keep_the_formation():
    s = render_motion("ring", seed=1, steps=3, size=(96, 72), n_robots=3, speed=0.5)
    f = data_synth.render("ring", seed=1, size=(96, 72), n_robots=3, cache=False)
    assert len(s.flat.views) == 9 and s.image(2, 1) == 5
    for k in range(3):
        shift = 0.5 * (k - 1)
        for i in range(3):
            v, v0 = s.frame(i, k), f.views[i]
            np.testing.assert_allclose(v.R, v0.R)
            c, c0 = -v.R.T @ v.t, -v0.R.T @ v0.t
            np.testing.assert_allclose(c - c0, [shift, 0.0, 0.0], atol=1e-12)
    # the middle step of an odd path is the snapshot's pose: same image up to sensor noise
    assert np.abs(s.frame(0, 1).image.astype(int) - f.views[0].image.astype(int)).mean() < 8


def test_consecutive_frames_of_one_robot_share_true_pairs():
    s = render_motion("ring", seed=0, steps=2, size=(320, 240), n_robots=2)
    a, b = (extract(s.frame(0, k), "sift", 300) for k in (0, 1))
    pairs = true_pairs(s.flat, s.image(0, 0), a.keypoints, s.image(0, 1), b.keypoints)
    assert len(pairs) > 50


def test_switching_graph_is_a_subset_that_recurs():
    s = render_motion("complete", seed=0, steps=8, size=(64, 48), n_robots=4, switching=True,
                      p_up=0.3, window=3)
    full = {tuple(e) for e in s.comm_edges.tolist()}
    for k in range(8):
        assert {tuple(e) for e in s.step_edges[k].tolist()} <= full
    for k in range(6):
        seen = set().union(*({tuple(e) for e in s.step_edges[j].tolist()} for j in range(k, k + 3)))
        assert seen == full
    assert any(len(e) < len(full) for e in s.step_edges)


@pytest.mark.parametrize("kw, match", [
    ({"steps": 0}, "steps"), ({"speed": -1.0}, "speed"), ({"p_up": 0.0}, "p_up"),
    # so far that the cameras' projections overflow: named, not an OverflowError
    ({"speed": 1e308}, r"speed 1e\+308: .*at most 1e\+06"),
    # not numbers: named, not a TypeError
    ({"speed": "1"}, r"speed '1'.*>= 0"), ({"speed": None}, "speed None"),
    ({"speed": True}, "speed True"), ({"p_up": "x"}, r"p_up 'x'.*\(0, 1\]"),
    ({"p_up": float("nan")}, "p_up nan"),
    # the window of the switching graph: an integer >= 1, with or without switching
    ({"window": 0}, r"window must be an integer >= 1, got 0"),
    ({"window": 1.5}, r"window must be an integer >= 1, got 1.5"),
    ({"window": "3"}, r"window must be an integer >= 1, got '3'"),
    ({"window": 0, "switching": True}, r"window .* got 0"),
    # a string is truthy: "no" drew a switching graph
    ({"switching": "no"}, r"switching 'no': expected True or False"),
    # frames beyond the machine's memory: refused before the first render, not killed
    ({"steps": 10**12}, r"steps 1000000000000: 2000000000000 frames of 64x48 .* machine's memory")])
def test_bad_parameters_are_named(kw, match):
    with pytest.raises(InputError, match=match):
        render_motion("ring", size=(64, 48), n_robots=2, **{"steps": 1, **kw})


def test_window_one_and_numpy_numbers_are_accepted():
    s = render_motion("ring", size=(64, 48), n_robots=3, steps=2, switching=True,
                      window=np.int64(1), p_up=np.float64(0.5), speed=np.float32(0.2))
    # a window of one step: every edge up at every step
    assert all(len(e) == len(s.comm_edges) for e in s.step_edges)


def test_a_numpy_seed_moves_as_the_same_python_int():
    """The scene of a numpy int64 seed was another one (seed * 1000 + 7 wrapped)."""
    a = render_motion("ring", seed=2**62, steps=1, size=(64, 48), n_robots=2)
    b = render_motion("ring", seed=np.int64(2**62), steps=1, size=(64, 48), n_robots=2)
    assert all(np.array_equal(x.image, y.image)
               for x, y in zip(a.flat.views, b.flat.views, strict=True))
