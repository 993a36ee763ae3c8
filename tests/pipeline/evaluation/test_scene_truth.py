"""A reconstruction judged against exact truth: Umeyama's similarity, pose errors in the
truth's gauge, wrong tracks from the depth of every pixel."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from pipeline.errors import InputError
from pipeline.evaluation.scene_truth import (
    SceneTruth,
    pose_errors,
    read_truth,
    umeyama,
    wrong_tracks,
)

W, H = 64, 48


def _plane_truth(n: int = 4) -> SceneTruth:
    """n cameras (not on one line) looking along +z at the plane z = 10 (exact depth)."""
    K = np.array([[50.0, 0, (W - 1) / 2], [0, 50.0, (H - 1) / 2], [0, 0, 1]])
    R = np.stack([np.eye(3)] * n)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    centres = np.c_[np.cos(a), np.sin(a), 0.3 * np.arange(n)]
    t = -centres
    depth = np.ones((n, H, W), np.float32) * (10.0 - centres[:, 2])[:, None, None].astype(np.float32)
    return SceneTruth([f"c{k}.png" for k in range(n)], np.stack([K] * n), R, t, depth)


def _project(truth: SceneTruth, k: int, X: np.ndarray) -> tuple[float, float]:
    x = truth.K[k] @ (truth.R[k] @ X + truth.t[k])
    return float(x[0] / x[2]) + 0.5, float(x[1] / x[2]) + 0.5  # COLMAP's convention


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**16), scale=st.floats(0.1, 10.0))
def test_umeyama_recovers_a_similarity(seed, scale):
    rng = np.random.default_rng(seed)
    src = rng.normal(size=(6, 3))
    R = Rotation.random(random_state=seed).as_matrix()
    c = rng.normal(size=3)
    s, R_est, c_est = umeyama(src, scale * src @ R.T + c)
    assert s == pytest.approx(scale, rel=1e-6)
    assert np.allclose(R_est, R, atol=1e-6) and np.allclose(c_est, c, atol=1e-5)


def test_pose_errors_are_zero_in_any_gauge_and_see_a_wrong_camera():
    truth = _plane_truth()
    # the same cameras in another gauge: world_est = (world_true - c) R_sᵀ / s, so
    # cam_from_est = (R R_sᵀ, s-scaled t)
    Rs, s, c = Rotation.from_euler("xyz", [0.3, -0.2, 1.0]).as_matrix(), 2.5, np.array([1, 2, 3.])
    poses = {}
    for k, name in enumerate(truth.names):
        R = truth.R[k] @ Rs
        centre = Rs.T @ (truth.centres()[k] - c) / s
        poses[name] = (R, -R @ centre)
    got = pose_errors(poses, truth)
    assert got["registered"] == 4
    assert got["rotation_deg"]["max"] < 1e-6 and got["position_m"]["max"] < 1e-6
    # one camera turned by 10 degrees about its own axis
    name = truth.names[1]
    R, t = poses[name]
    turn = Rotation.from_euler("z", 10, degrees=True).as_matrix()
    poses[name] = (turn @ R, turn @ t)
    got = pose_errors(poses, truth)
    assert got["rotation_deg"]["max"] == pytest.approx(10.0, abs=1e-3)
    assert pose_errors(dict(list(poses.items())[:2]), truth)["rotation_deg"] is None


def test_tracks_of_one_point_are_right_and_a_swapped_observation_is_wrong():
    truth = _plane_truth()
    X, Y = np.array([0.2, 0.1, 10.0]), np.array([0.9, -0.4, 10.0])
    right = [(n, *_project(truth, k, X)) for k, n in enumerate(truth.names)]
    wrong = right[:2] + [(truth.names[2], *_project(truth, 2, Y))]
    single = right[:1]
    got = wrong_tracks([right, wrong, single], truth)
    assert (got["points"], got["judged"], got["wrong"]) == (3, 2, 1)
    # a depth edge is not judged
    truth.depth[2][:, W // 2:] = 20.0
    on_edge = [(n, *_project(truth, k, np.array([0.0, 0.0, 10.0])))
               for k, n in enumerate(truth.names)]
    assert wrong_tracks([on_edge], truth)["judged"] in (0, 1)


def test_a_reconstruction_without_points_has_no_wrong_track():
    """Regression: a model with no points (or tracks of no judged observation) failed on the
    bookkeeping of empty tracks."""
    truth = _plane_truth()
    got = wrong_tracks([], truth)
    assert (got["points"], got["judged"], got["wrong"], got["wrong_fraction"]) == (0, 0, 0, 0.0)
    assert wrong_tracks([[("other.png", 1.0, 1.0)]], truth)["judged"] == 0


def test_truth_file_round_trip_and_bad_files(tmp_path):
    truth = _plane_truth(3)
    np.savez(tmp_path / "truth.npz", names=np.array(truth.names), K=truth.K, R=truth.R,
             t=truth.t, depth=truth.depth)
    back = read_truth(tmp_path)
    assert back.names == truth.names and np.array_equal(back.depth, truth.depth)
    with pytest.raises(InputError, match="no truth file"):
        read_truth(tmp_path / "missing")
    np.savez(tmp_path / "truth.npz", names=np.array(truth.names), K=truth.K[:2], R=truth.R,
             t=truth.t, depth=truth.depth)
    with pytest.raises(InputError, match="do not describe 3 images"):
        read_truth(tmp_path)


def test_wrong_links_from_the_depth():
    from pipeline.evaluation.scene_truth import wrong_links
    from pipeline.types import Links

    truth = _plane_truth(3)
    X, Y = np.array([0.2, 0.1, 10.0]), np.array([0.9, -0.4, 10.0])
    kp = [np.array([_project(truth, k, X), _project(truth, k, Y)]) - 0.5 for k in range(3)]
    # (0, X)-(1, X) right, (0, X)-(2, Y) wrong, (1, Y)-(2, Y) right
    links = Links([0, 0, 1], [0, 0, 1], [1, 2, 2], [0, 1, 1])
    wrong, judged = wrong_links(truth.names, kp, links, truth)
    assert judged.all() and wrong.tolist() == [False, True, False]


def test_a_link_with_an_end_off_the_depth_is_not_judged_nor_wrong():
    from pipeline.evaluation.scene_truth import wrong_links
    from pipeline.types import Links

    truth = _plane_truth(3)
    X, Y = np.array([0.2, 0.1, 10.0]), np.array([0.9, -0.4, 10.0])
    kp = [np.array([_project(truth, k, X), _project(truth, k, Y)]) - 0.5 for k in range(3)]
    truth.depth[2] = np.nan  # camera 2 sees no depth: its ends have no true point
    links = Links([0, 0, 1], [0, 0, 1], [1, 2, 2], [0, 1, 1])
    wrong, judged = wrong_links(truth.names, kp, links, truth)
    assert judged.tolist() == [True, False, False]
    assert wrong.tolist() == [False, False, False]


def test_a_track_of_two_observations_is_judged():
    # two observations are enough to see two different points (one is not)
    truth = _plane_truth()
    X, Y = np.array([0.2, 0.1, 10.0]), np.array([0.9, -0.4, 10.0])
    right = [(truth.names[k], *_project(truth, k, X)) for k in (0, 1)]
    wrong = [(truth.names[0], *_project(truth, 0, X)), (truth.names[3], *_project(truth, 3, Y))]
    got = wrong_tracks([right, wrong, right[:1]], truth)
    assert (got["points"], got["judged"], got["wrong"], got["wrong_fraction"]) == (3, 2, 1, 0.5)
