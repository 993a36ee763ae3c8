"""The fusion stage leaves out a track that holds two features of one camera (conflictive):
it fuses no point from it and votes no observation of it out."""

import numpy as np

from data_synth.formations import look_at
from pipeline.fusion.landmarks import fuse_tracks
from pipeline.types import Features, Links, View


def _rig(second_feature_of_camera_0: bool):
    """Five cameras in a row see point P (one feature each), cameras 0-3 all linked, camera 4
    linked to camera 1 and to camera 0's feature, or (``second_feature_of_camera_0``) to a
    second feature of camera 0, 3 px beside the first: the track then holds camera 0 twice
    (links are one-to-one per camera pair, Assumption 2.2)."""
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    P = np.array([0.0, 0.0, 6.0])
    views, feats = [], []
    for v in range(5):
        R, t = look_at([0.5 * v - 1.0, 0.0, 0.0], [0.0, 0.0, 6.0], up=(0.0, 1.0, 0.0))
        p = K @ (R @ P + t)
        uv = [p[:2] / p[2]]
        if v == 0 and second_feature_of_camera_0:
            uv.append(uv[0] + [3.0, 0.0])
        views.append(View(f"cam{v}", np.zeros((240, 320), np.uint8), K, R, t))
        feats.append(Features(np.array(uv, np.float32), np.zeros((len(uv), 4), np.float32),
                              np.ones(len(uv), np.float32), "sift"))
    pairs = [(i, 0, j, 0) for i in range(4) for j in range(i + 1, 4)]
    pairs += [(0, 1 if second_feature_of_camera_0 else 0, 4, 0), (1, 0, 4, 0)]
    ci, fi, cj, fj = (np.array(a) for a in zip(*pairs, strict=True))
    edges = np.array([(i, j) for i in range(5) for j in range(i + 1, 5)])
    return views, feats, Links(ci, fi, cj, fj), edges


def test_a_track_with_two_features_of_one_camera_is_not_fused():
    views, feats, links, edges = _rig(second_feature_of_camera_0=False)
    fr = fuse_tracks(views, feats, links, edges)
    assert len(fr.points) == 1  # the same track without the second feature: fused
    views, feats, links, edges = _rig(second_feature_of_camera_0=True)
    fr = fuse_tracks(views, feats, links, edges)
    assert len(fr.points) == 0
    assert fr.obs_inlier.all() and not fr.cut_links.any()
