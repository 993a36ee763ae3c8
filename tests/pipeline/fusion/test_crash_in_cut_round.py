"""A robot that crashes while the fusion stage's ``fusion-cut`` notices go out (its last
round) never finished: the stage reports it crashed, does not judge its observations and cuts
none of its links, as for a crash earlier in the stage (README, "Transports": a robot crashed
during fusion is listed in ``fusion.crashed``, votes in no decision and has none of its links
cut by fusion)."""

import sys
from pathlib import Path

import numpy as np

from pipeline.fusion.landmarks import fuse_tracks
from pipeline.transport.simulated import Network, NetworkOptions

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_robot import _ring_rig  # noqa: E402


def test_a_robot_crashed_in_any_round_of_the_stage_is_reported_and_keeps_its_links():
    views, feats, links, edges, labels = _ring_rig()
    names = np.concatenate(labels)
    touching = (links.cam_i == 3) | (links.cam_j == 3)
    fault_free = fuse_tracks(views, feats, links, edges, track_labels=names)
    assert (fault_free.cut_links & touching).any()     # robot 3 or a neighbour has outliers
    reached = 0
    for r in range(1, 12):
        net = Network(len(views), edges, NetworkOptions(crash_at={3: r}))
        fr = fuse_tracks(views, feats, links, edges, track_labels=names, transport=net)
        if net.alive(3):                               # the stage ended before round r
            assert fr.stats["crashed"] == []
            continue
        reached += 1
        assert fr.stats["crashed"] == [3], r
        assert not (fr.cut_links & touching).any(), r
        assert fr.obs_inlier[fr.obs_cam == 3].all(), r
    assert reached >= 3
