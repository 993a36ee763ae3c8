"""An outlier leaves its landmark (pipeline.fusion.landmarks, "Outliers leave the landmark"):
the links from the observations voted out to the landmark's others are cut, and a link
between two outliers that saw one other point stays (a robot standing still included: no
baseline, their rays agree), while one between two outliers that cannot be one point is cut.
Cutting every link at an outlier cut those right links too (most of the good links fusion
cut: a robot's frames standing still, a pair of robots that saw one point a wrong link
joined to the track). The robots, one by one, cut the same links as the vectorized stage."""

import numpy as np
import pytest

from data_synth.formations import look_at
from pipeline.fusion.landmarks import fuse_tracks
from pipeline.fusion.robot import FusionOptions, FusionRobot
from pipeline.fusion.robot_loops import run_fusion_locally
from pipeline.transport.local import LocalTeam
from pipeline.types import Features, Links, View


def _rig(last="Q"):
    """Seven cameras in a row, complete comm graph, one track of one feature per camera:
    cameras 0-4 see point P, camera 5 sees point Q, 1.5 m beside it (a wrong link joined the
    two groups), and camera 6 (``last``): Q too (``"Q"``), Q from camera 5's pose (``"still"``:
    a robot standing still), or a third point R, 1 m from Q (``"R"``); every pair of cameras
    is linked."""
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    P, Q = np.array([0.0, 0.0, 6.0]), np.array([1.5, 0.3, 6.5])
    rng = np.random.default_rng(3)
    views, feats = [], []
    for v in range(7):
        u = 5 if (v == 6 and last == "still") else v
        R, t = look_at([0.5 * u - 1.5, 0.05 * u, 0.0], [0.0, 0.0, 6.0], up=(0.0, 1.0, 0.0))
        X = P if v < 5 else (Q + [0.0, 1.0, 0.0] if (v == 6 and last == "R") else Q)
        p = K @ (R @ X + t)
        uv = p[:2] / p[2] + rng.normal(0, 0.2, 2)
        views.append(View(f"cam{v}", np.zeros((240, 320), np.uint8), K, R, t))
        feats.append(Features(uv[None].astype(np.float32), np.zeros((1, 4), np.float32),
                              np.ones(1, np.float32), "sift"))
    edges = np.array([(i, j) for i in range(7) for j in range(i + 1, 7)])
    links = Links(edges[:, 0], np.zeros(len(edges), int), edges[:, 1], np.zeros(len(edges), int))
    return views, feats, links, edges


@pytest.mark.parametrize("consensus", ["exact", "metropolis"])
@pytest.mark.parametrize("last, apart", [("Q", False), ("still", False), ("R", True)])
def test_the_outliers_keep_their_link_to_each_other(consensus, last, apart):
    views, feats, links, edges = _rig(last)
    fr = fuse_tracks(views, feats, links, edges, consensus=consensus)
    outlier = ~fr.obs_inlier[np.argsort(fr.obs_cam)]
    assert outlier.tolist() == [False] * 5 + [True, True]
    pair = [(int(a), int(b)) for a, b in zip(links.cam_i, links.cam_j, strict=True)]
    cut = {p for p, c in zip(pair, fr.cut_links, strict=True) if c}
    # P's observers keep their links, every link between the groups goes; the two outliers
    # keep theirs when they can be one point (Q twice, from two poses or from one)
    assert cut == {(i, j) for i in range(5) for j in (5, 6)} | ({(5, 6)} if apart else set())

    # each robot on its own cuts its ends of the same links
    labels = [np.array([0]) for _ in views]
    robots = [FusionRobot(i, len(views), edges, labels[i], feats[i].keypoints, views[i].K,
                          views[i].R, views[i].t, FusionOptions(consensus=consensus))
              for i in range(len(views))]
    LocalTeam(len(views), edges).run(lambda end: run_fusion_locally(robots[end.id], end))
    for i, r in enumerate(robots):
        mine = np.flatnonzero((links.cam_i == i) | (links.cam_j == i))
        nbr = np.where(links.cam_i[mine] == i, links.cam_j[mine], links.cam_i[mine])
        got = r.cut_rows(nbr, np.zeros(len(mine), int), np.zeros(len(mine), int))
        np.testing.assert_array_equal(got, fr.cut_links[mine])
