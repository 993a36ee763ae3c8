"""A robot that observes no track of the fusion stage (pipeline.fusion.robot) only relays the
termination wave, in either consensus mode, and the team still cuts the vectorized stage's
links."""

import numpy as np
import pytest

from data_synth.formations import look_at
from pipeline.fusion.landmarks import fuse_tracks
from pipeline.fusion.robot import FusionOptions, FusionRobot
from pipeline.fusion.robot_loops import run_fusion_locally
from pipeline.transport.local import LocalTeam
from pipeline.types import Features, Links, View


@pytest.mark.parametrize("consensus", ["exact", "metropolis"])
def test_a_robot_that_sees_no_track_finishes_with_the_others(consensus):
    """Cameras 0-2 see one point (camera 2's keypoint far off), camera 3 sees nothing."""
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    P = np.array([0.0, 0.0, 6.0])
    views, feats = [], []
    for v in range(4):
        R, t = look_at([0.6 * v - 0.9, 0.0, 0.0], P, up=(0.0, 1.0, 0.0))
        views.append(View(f"cam{v}", np.zeros((240, 320), np.uint8), K, R, t))
        p = K @ (R @ P + t)
        uv = (p[:2] / p[2] + (40.0 if v == 2 else 0.0))[None] if v < 3 else np.zeros((0, 2))
        feats.append(Features(uv.astype(np.float32), np.zeros((len(uv), 4), np.float32),
                              np.ones(len(uv), np.float32), "sift"))
    edges = np.array([(0, 1), (0, 2), (1, 2), (2, 3)])
    links = Links([0, 0, 1], [0, 0, 0], [1, 2, 2], [0, 0, 0])
    labels = [np.array([0]), np.array([0]), np.array([0]), np.zeros(0, np.int64)]
    ref = fuse_tracks(views, feats, links, edges, track_labels=np.concatenate(labels),
                      consensus=consensus)
    robots = [FusionRobot(i, 4, edges, labels[i], feats[i].keypoints, views[i].K, views[i].R,
                          views[i].t, FusionOptions(consensus=consensus)) for i in range(4)]
    outs = LocalTeam(4, edges).run(lambda end: run_fusion_locally(robots[end.id], end))
    assert ref.cut_links.tolist() == [False, True, True]          # camera 2 leaves the landmark
    assert all(o is not None and o["lost"] == [] for o in outs) and robots[3].done
    for i in range(3):
        rows = np.flatnonzero((links.cam_i == i) | (links.cam_j == i))
        nbr = np.where(links.cam_i[rows] == i, links.cam_j[rows], links.cam_i[rows])
        zeros = np.zeros(len(rows), np.int64)
        np.testing.assert_array_equal(robots[i].cut_rows(nbr, zeros, zeros), ref.cut_links[rows])
