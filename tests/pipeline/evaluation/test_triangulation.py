import numpy as np
import pycolmap
import pytest

from pipeline.colmap import build_reconstruction
from pipeline.evaluation.triangulation import (
    medoid,
    medoids,
    reprojection_errors,
    triangulate_tracks,
    write_reconstruction,
)
from pipeline.types import Features, Links, View


def _look_at(center, target):
    z = target - center
    z /= np.linalg.norm(z)
    x = np.cross(np.array([0.0, -1.0, 0.0]), z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ center


@pytest.fixture
def scene():
    """Three cameras looking at 5 points; feature r of every camera images point r."""
    rng = np.random.default_rng(0)
    X = rng.uniform([-1, -1, 4], [1, 1, 6], size=(5, 3))
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    views, feats, gts = [], [], []
    for k, cx in enumerate([-1.0, 0.0, 1.0]):
        R, t = _look_at(np.array([cx, 0.0, 0.0]), np.array([0.0, 0.0, 5.0]))
        x = (K @ (X @ R.T + t).T).T
        kp = (x[:, :2] / x[:, 2:]).astype(np.float32)
        views.append(View(f"cam{k}", np.zeros((240, 320, 3), np.uint8), K, R, t))
        feats.append(Features(kp, np.zeros((5, 128), np.float32), np.ones(5, np.float32), "sift"))
        gts.append(X.copy())
    return views, feats, gts, X


def _chain_links(n_points):
    r = np.arange(n_points)
    return Links(np.r_[np.zeros(n_points), np.ones(n_points)], np.r_[r, r],
                 np.r_[np.ones(n_points), np.full(n_points, 2)], np.r_[r, r])


def test_clean_tracks_triangulate_exactly(scene):
    views, feats, gts, X = scene
    tri = triangulate_tracks(views, feats, _chain_links(5), gt_points=gts)
    s = tri.summary()
    assert s["tracks"] == 5 and s["triangulated_tracks"] == 5
    assert s["inlier_ratio"] == 1.0
    assert s["median_reprojection_error_px"] < 1e-3
    assert s["median_3d_error"] < 1e-4
    order = np.argsort([t.min() for t in tri.track_features])
    assert np.allclose(tri.xyz[order], X, atol=1e-4)


def test_wrong_observation_is_rejected(scene):
    views, feats, gts, X = scene
    # a 4th camera whose feature 0 images point 3 but is linked into track 0
    views = views + [views[1]]
    kp = feats[1].keypoints.copy()
    kp[0] = kp[3]
    feats = feats + [Features(kp, feats[1].descriptors, feats[1].scales, "sift")]
    links = _chain_links(5)
    links = Links(np.r_[links.cam_i, 2], np.r_[links.feat_i, 0], np.r_[links.cam_j, 3],
                  np.r_[links.feat_j, 0])
    tri = triangulate_tracks(views, feats, links)
    k = tri.track_of_feature[0]
    assert tri.ok[k]
    assert tri.inliers[k].sum() == 3
    assert tri.summary()["tracks_with_rejected_observation"] == 1


def test_association_sets_skip_singletons():
    from pipeline.association import association_sets

    links = Links([0], [1], [1], [0])
    track_of_feature, tracks = association_sets([3, 2], links)
    assert len(tracks) == 1
    assert track_of_feature.tolist() == [-1, 0, -1, 0, -1]


def test_written_model_loads_back(scene, tmp_path):
    views, feats, gts, X = scene
    tri = triangulate_tracks(views, feats, _chain_links(5))
    write_reconstruction(tmp_path / "sparse", views, feats, tri)
    rec = pycolmap.Reconstruction(str(tmp_path / "sparse"))
    assert rec.num_images() == 3
    assert rec.num_points3D() == 5
    assert build_reconstruction(views, feats).num_images() == 3
    lengths = sorted(p.track.length() for p in rec.points3D.values())
    assert lengths == [3] * 5


def test_written_points_take_the_colour_of_their_first_observation(scene, tmp_path):
    views, feats, gts, X = scene
    for k, v in enumerate(views):  # each camera's image a distinct colour per column
        v.image[:] = 0
        v.image[:, :, 0] = np.arange(320, dtype=np.uint8)[None, :]
        v.image[:, :, 1] = 10 * (k + 1)
    rec = write_reconstruction(tmp_path / "sparse", views, feats,
                               triangulate_tracks(views, feats, _chain_links(5)))
    for point in rec.points3D.values():
        first = min(point.track.elements, key=lambda e: e.image_id)
        assert first.image_id == 1  # camera 0 is the first observation of every track
        u = int(np.clip(round(float(feats[0].keypoints[first.point2D_idx][0])), 0, 319))
        assert point.color.tolist() == [u % 256, 10, 0]


def test_conflictive_track_is_not_written(scene, tmp_path):
    views, feats, gts, X = scene
    # features 0 and 1 of camera 0 half a pixel apart, both in point 0's track: both are
    # inliers, and a COLMAP track holds one observation per image
    feats[0].keypoints[1] = feats[0].keypoints[0] + 0.5
    links = Links(np.r_[0, 1, 0], np.r_[0, 0, 1], np.r_[1, 2, 2], np.r_[0, 0, 0])
    tri = triangulate_tracks(views, feats, links)
    rec = write_reconstruction(tmp_path / "sparse", views, feats, tri)
    assert len(tri.track_features) == 1 and tri.ok[0] and tri.inliers[0].all()
    assert rec.num_points3D() == 0


def test_medoids_equal_medoid_bit_for_bit():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(200, 3)) * 10
    pts[rng.random(200) < 0.1, 1] = np.nan
    groups = [rng.choice(200, size=int(k), replace=False) for k in rng.integers(1, 9, size=60)]
    groups.append(np.flatnonzero(np.isnan(pts[:, 1]))[:3])   # no finite point: nan row
    got = medoids(pts, groups)
    want = np.stack([medoid(pts[g]) for g in groups])
    assert got.tobytes() == want.tobytes()
    assert np.isnan(got[-1]).all()
    assert medoids(pts, []).shape == (0, 3)


def test_reprojection_errors_match_the_projection(scene):
    views, feats, gts, X = scene
    cams = np.array([0, 1, 2, 1])
    pts = np.stack([X[0], X[1], X[2], X[3]])
    kp = np.stack([feats[c].keypoints[r] for c, r in zip(cams, [0, 1, 2, 3], strict=True)]).astype(float)
    kp[3] += [3.0, 4.0]  # 5 px off
    err = reprojection_errors(views, pts, cams, kp)
    assert np.allclose(err[:3], 0, atol=1e-3) and err[3] == pytest.approx(5.0, abs=1e-3)
    behind = reprojection_errors(views, np.array([[0.0, 0.0, -5.0]]), np.array([1]), kp[:1])
    assert np.isinf(behind).all()
    for k, c in enumerate(cams):  # the arithmetic of one K (R X + t) at a time
        v = views[c]
        x = v.K @ (v.R @ pts[k] + v.t)
        assert err[k] == float(np.linalg.norm(x[:2] / x[2] - kp[k]))
