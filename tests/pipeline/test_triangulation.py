import numpy as np
import pycolmap
import pytest

from pipeline.colmap import build_reconstruction
from pipeline.triangulation import triangulate_tracks, write_reconstruction
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
