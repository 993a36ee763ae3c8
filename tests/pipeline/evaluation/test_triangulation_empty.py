"""Triangulating no track: the ratios and means of the summary are no figures (None), like the
reprojection errors, not a 0 that reads as every observation rejected."""

import numpy as np

from pipeline.evaluation.triangulation import triangulate_tracks
from pipeline.types import Features, Links, View


def test_no_track_has_no_inlier_ratio():
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    views = [View(f"cam{k}", np.zeros((240, 320, 3), np.uint8), K, np.eye(3),
                  np.array([float(k), 0.0, 0.0])) for k in range(2)]
    feats = [Features(np.zeros((3, 2), np.float32), np.zeros((3, 128), np.float32),
                      np.ones(3, np.float32), "sift") for _ in range(2)]
    none = Links(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
                 np.zeros(0, np.int64))
    s = triangulate_tracks(views, feats, none).summary()
    assert s["tracks"] == 0 and s["observations"] == 0
    assert s["inlier_ratio"] is None
    assert s["mean_reprojection_error_px"] is None
