"""The triangulation figures of a report, from hand-built tracks."""

import numpy as np

from pipeline.evaluation.triangulation import TrackTriangulation


def test_summary_counts_tracks_not_rejected_observations():
    # track 0: 4 observations, 2 rejected; track 1: 3, all inliers; track 2 failed (its
    # rejections are no track's), 2 observations
    tri = TrackTriangulation(
        track_of_feature=np.array([0, 0, 0, 0, 1, 1, 1, 2, 2]),
        track_features=[np.arange(4), np.arange(4, 7), np.arange(7, 9)],
        xyz=np.array([[0.0, 0, 1], [1.0, 0, 1], [np.nan] * 3]),
        ok=np.array([True, True, False]),
        inliers=[np.array([True, False, True, False]), np.ones(3, bool), np.zeros(2, bool)],
        reproj_error_px=[np.array([1.0, 9.0, 3.0, 9.0]), np.array([0.5, 0.5, 2.0]),
                         np.array([7.0, 7.0])],
        gt_error=np.array([0.1, 0.3, np.nan]))
    s = tri.summary()
    assert s["tracks"] == 3 and s["triangulated_tracks"] == 2
    assert s["observations"] == 9 and s["inlier_observations"] == 5
    assert s["tracks_with_rejected_observation"] == 1
    assert s["inlier_ratio"] == 5 / 9
    assert s["mean_reprojection_error_px"] == 7.0 / 5           # inliers of the triangulated
    assert s["median_reprojection_error_px"] == 1.0
    assert abs(s["median_3d_error"] - 0.2) <= 1e-12
