"""pipeline.colmap: database write-and-reload, reading COLMAP-made databases, cleaned copies,
incremental mapping on downscaled Sceaux photographs."""

import hashlib

import numpy as np
import pycolmap
import pytest

from pipeline import colmap
from pipeline.errors import InputError
from pipeline.types import Features, Links, View


def _views_and_features(n=3, m=40, seed=0, known=(True, False, True)):
    rng = np.random.default_rng(seed)
    views, feats = [], []
    for k in range(n):
        K = np.array([[300.0 + k, 0, 159.5], [0, 301.0, 119.5], [0, 0, 1]])
        views.append(View(f"img{k}.png", np.zeros((240, 320, 3), np.uint8), K,
                          intrinsics_known=known[k % len(known)]))
        kp = rng.uniform([0, 0], [319, 239], size=(m, 2)).astype(np.float32)
        feats.append(Features(kp, np.zeros((m, 128), np.float32), np.ones(m, np.float32), "sift"))
    return views, feats


def _links(n=3, m=40, seed=0):
    """One-to-one random links on every camera pair (20 per pair)."""
    rng = np.random.default_rng(seed)
    parts = []
    for i in range(n):
        for j in range(i + 1, n):
            r = rng.permutation(m)[:20]
            s = rng.permutation(m)[:20]
            parts.append((np.full(20, i), r, np.full(20, j), s))
    ci, fi, cj, fj = (np.concatenate(c) for c in zip(*parts, strict=True))
    return Links(ci, fi, cj, fj)


def _link_set(links: Links, mask=None):
    idx = np.arange(len(links)) if mask is None else np.flatnonzero(mask)
    return {(int(links.cam_i[k]), int(links.feat_i[k]), int(links.cam_j[k]), int(links.feat_j[k]))
            for k in idx}


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_write_and_reload_round_trip(tmp_path):
    views, feats = _views_and_features()
    links = _links()
    keep = np.random.default_rng(1).random(len(links)) < 0.7
    db_path = colmap.write_database(tmp_path / "out.db", views, feats, links, keep)
    contents = colmap.read_database(db_path)
    assert contents.names == [v.name for v in views]
    for kp, f in zip(contents.keypoints, feats, strict=True):
        assert np.allclose(kp, f.keypoints, atol=1e-4)  # +0.5 on write, -0.5 on read
    assert _link_set(contents.links) == _link_set(links, keep)
    assert not contents.not_one_to_one.any()
    with pycolmap.Database.open(db_path) as db:
        # COLMAP pixel convention: principal point + 0.5; one trivial rig and frame per image
        cam = db.read_camera(1)
        assert cam.model == pycolmap.CameraModelId.PINHOLE
        assert np.allclose(cam.params, [300.0, 301.0, 160.0, 120.0])
        # a guessed K: COLMAP's model for photographs, one focal length sqrt(fx fy), no
        # radial term yet, no prior, refined by the mapper
        guess = db.read_camera(2)
        assert guess.model == pycolmap.CameraModelId.SIMPLE_RADIAL
        assert np.allclose(guess.params, [np.sqrt(301.0 * 301.0), 160.0, 120.0, 0.0])
        assert cam.has_prior_focal_length and not guess.has_prior_focal_length
        assert db.num_rigs() == db.num_frames() == db.num_images() == 3
        # the raw matches table holds every link, kept or not
        assert db.num_matches() == len(links)
        pair_ids, geoms = db.read_two_view_geometries()
        configs = {tuple(int(v) for v in pycolmap.pair_id_to_image_pair(p)): g.config
                   for p, g in zip(pair_ids, geoms, strict=True)}
    # image 1 (known) with 2 (guess) -> uncalibrated; 1 with 3 (both known) -> calibrated
    assert configs[(1, 2)] == pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED
    assert configs[(1, 3)] == pycolmap.TwoViewGeometryConfiguration.CALIBRATED


def test_write_refuses_existing_file(tmp_path):
    views, feats = _views_and_features()
    (tmp_path / "x.db").write_bytes(b"keep me")
    with pytest.raises(InputError, match="already exists"):
        colmap.write_database(tmp_path / "x.db", views, feats, _links())
    assert (tmp_path / "x.db").read_bytes() == b"keep me"


def test_read_orders_cameras_by_name_and_flips_pairs(tmp_path):
    """A database whose image ids run against name order (as COLMAP may write them)."""
    views, feats = _views_and_features(n=2)
    links = Links([0, 0], [3, 5], [1, 1], [7, 9])
    path = colmap.write_database(tmp_path / "a.db", views[::-1], feats[::-1],
                                 Links([0, 0], [7, 9], [1, 1], [3, 5]))
    contents = colmap.read_database(path)
    assert contents.names == ["img0.png", "img1.png"]
    assert contents.image_ids.tolist() == [2, 1]
    assert _link_set(contents.links) == _link_set(links)


def test_cleaned_copy_holds_exactly_the_kept_links_and_input_is_untouched(tmp_path):
    views, feats = _views_and_features()
    links = _links()
    src = colmap.write_database(tmp_path / "in.db", views, feats, links)
    before = _sha(src)
    contents = colmap.read_database(src)
    keep = np.ones(len(contents.links), bool)
    keep[::3] = False
    # one pair loses every inlier: it keeps its row with no inliers
    keep[(contents.links.cam_i == 1) & (contents.links.cam_j == 2)] = False
    out = colmap.write_cleaned_database(contents, tmp_path / "clean.db", keep)
    assert _sha(src) == before
    cleaned = colmap.read_database(out)
    assert _link_set(cleaned.links) == _link_set(contents.links, keep)
    assert cleaned.pairs_without_inliers == 1
    with pycolmap.Database.open(out) as db:
        assert db.num_matches() == len(links)  # raw matches are copied unchanged


def test_cleaned_copy_refuses_to_overwrite_input(tmp_path):
    views, feats = _views_and_features()
    src = colmap.write_database(tmp_path / "in.db", views, feats, _links())
    contents = colmap.read_database(src)
    with pytest.raises(InputError, match="never modified"):
        colmap.write_cleaned_database(contents, src, np.ones(len(contents.links), bool))


def test_not_one_to_one_inliers_are_flagged(tmp_path):
    views, feats = _views_and_features(n=2)
    path = tmp_path / "many.db"
    with pycolmap.Database.open(path) as db:
        for v in views:
            cid = db.write_camera(pycolmap.Camera(model="PINHOLE", width=320, height=240,
                                                  params=[300, 300, 160, 120]))
            iid = db.write_image(pycolmap.Image(name=v.name, camera_id=cid))
            db.write_keypoints(iid, np.zeros((10, 2), np.float32))
        inl = np.array([[0, 0], [1, 0], [2, 2], [2, 3], [4, 4]], np.uint32)  # 0,1 -> 0; 2 -> 2,3
        db.write_two_view_geometry(1, 2, pycolmap.TwoViewGeometry(
            config=pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED, inlier_matches=inl))
    contents = colmap.read_database(path)
    # every inlier of a feature linked twice into the other image: no score tells which is
    # right (keeping the first one cost the mapper an image of a cross-check-off database)
    assert contents.not_one_to_one.tolist() == [True, True, True, True, False]


def test_image_without_keypoints_and_six_column_keypoints(tmp_path):
    """COLMAP's SIFT stores (x, y, a11, a12, a21, a22); an image may have no keypoints row."""
    path = tmp_path / "six.db"
    kp6 = np.zeros((4, 6), np.float32)
    kp6[:, :2] = [[10.5, 20.5], [30.5, 40.5], [50.5, 60.5], [70.5, 80.5]]
    with pycolmap.Database.open(path) as db:
        ids = []
        for name in ("a.jpg", "b.jpg", "c.jpg"):
            cid = db.write_camera(pycolmap.Camera(model="PINHOLE", width=320, height=240,
                                                  params=[300, 300, 160, 120]))
            ids.append(db.write_image(pycolmap.Image(name=name, camera_id=cid)))
        db.write_keypoints(ids[0], kp6)
        db.write_keypoints(ids[1], kp6)
        db.write_two_view_geometry(ids[0], ids[1], pycolmap.TwoViewGeometry(
            config=pycolmap.TwoViewGeometryConfiguration.CALIBRATED,
            inlier_matches=np.array([[0, 1], [2, 3]], np.uint32)))
    contents = colmap.read_database(path)
    assert np.allclose(contents.keypoints[0], [[10, 20], [30, 40], [50, 60], [70, 80]])
    assert contents.features_per_camera.tolist() == [4, 4, 0]
    assert _link_set(contents.links) == {(0, 0, 1, 1), (0, 2, 1, 3)}


def test_relative_rotations_of_a_rendered_pose_graph(tmp_path):
    """Three calibrated cameras round a point cloud: each pair's rotation from its stored
    geometry is the true ``R_j R_iᵀ`` (to 0.5°), in name order whatever the stored order."""
    from scipy.spatial.transform import Rotation

    from data_synth.formations import look_at

    rng = np.random.default_rng(2)
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    poses = [look_at([8 * np.sin(a), -8 * np.cos(a), 1.0], [0, 0, 0])
             for a in np.deg2rad([-25.0, 0.0, 30.0])]
    X = rng.uniform(-1.5, 1.5, size=(50, 3))
    kps = []
    for R, t in poses:
        x = (K @ (R @ X.T + t[:, None])).T
        kps.append((x[:, :2] / x[:, 2:]).astype(np.float32))
    # names sort as 2, 0, 1: the stored image order is not the name order
    views = [View(name, np.zeros((240, 320, 3), np.uint8), K) for name in ("b", "c", "a")]
    feats = [Features(k, np.zeros((50, 128), np.float32), np.ones(50, np.float32), "sift")
             for k in kps]
    rows = [(i, p, j, p) for i, j in ((0, 1), (0, 2), (1, 2)) for p in range(50)]
    colmap.write_database(tmp_path / "r.db", views, feats, Links(*np.array(rows).T))
    contents = colmap.read_database(tmp_path / "r.db")
    pairs, rotations, inliers = colmap.relative_rotations(contents)
    assert pairs.tolist() == [[0, 1], [0, 2], [1, 2]] and inliers.tolist() == [50, 50, 50]
    camera_of = [2, 0, 1]  # camera i (name order) is view camera_of[i]
    for (i, j), R in zip(pairs.tolist(), rotations, strict=True):
        true = poses[camera_of[j]][0] @ poses[camera_of[i]][0].T
        err = Rotation.from_matrix(R @ true.T).magnitude()
        assert np.degrees(err) < 0.5, (i, j)


def test_database_without_two_view_geometries(tmp_path):
    views, feats = _views_and_features(n=2)
    path = colmap.write_database(tmp_path / "raw.db", views, feats,
                                 Links(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0)))
    with pytest.raises(InputError, match="no two-view geometries"):
        colmap.read_database(path)


def test_database_of_matches_never_verified_names_them(tmp_path):
    """matched with geometric verification skipped: the matches table holds the matches, no
    pair has a two-view geometry; the message said to run the matcher that had run"""
    import sqlite3

    views, feats = _views_and_features(n=3)
    path = colmap.write_database(tmp_path / "unverified.db", views, feats,
                                 Links([0, 0, 1], [1, 2, 3], [1, 2, 2], [2, 3, 4]))
    with sqlite3.connect(path) as con:
        con.execute("DELETE FROM two_view_geometries")
    with pytest.raises(InputError, match=r"its 3 matches of 3 image pairs were never "
                                         r"geometrically verified .*pycolmap.verify_matches"):
        colmap.read_database(path)


def test_database_whose_geometries_have_no_inliers_reads_as_no_link(tmp_path):
    views, feats = _views_and_features(n=2)
    links = Links([0], [1], [1], [2])
    path = colmap.write_database(tmp_path / "failed.db", views, feats, links, keep=[False])
    contents = colmap.read_database(path)
    assert len(contents.links) == 0 and contents.pairs_without_inliers == 1


def test_not_a_database(tmp_path):
    (tmp_path / "x.db").write_text("hello")
    with pytest.raises(InputError, match="not an SQLite file"):
        colmap.read_database(tmp_path / "x.db")
    with pytest.raises(InputError, match="no such file"):
        colmap.read_database(tmp_path / "missing.db")


@pytest.fixture(scope="module")
def sceaux_matches(sceaux_small):
    from pipeline.commgraph import comm_graph
    from pipeline.inputs.photos import load_folder
    from pipeline.matching.features import extract_all
    from pipeline.matching.pairs import match_edges

    views = load_folder(sceaux_small, max_size=640)
    feats = extract_all(views, "sift", 1500)
    edges = comm_graph("complete", [v.name for v in views])
    return views, feats, Links.from_matches(match_edges(feats, views, edges))


def test_incremental_mapping_on_sceaux(sceaux_matches, tmp_path):
    views, feats, links = sceaux_matches
    path = colmap.write_database(tmp_path / "sceaux.db", views, feats, links)
    result = colmap.incremental_mapping(path)
    s = result.summary()
    assert s["images"] == 4 and s["models"] >= 1
    assert s["registered_images"] >= 3
    assert s["points"] > 100
    assert 2.0 <= s["mean_track_length"] <= 4.0  # at most one observation per image
    assert 0.0 < s["mean_reprojection_error"] < 2.0
    assert isinstance(result.reconstruction, pycolmap.Reconstruction)
    assert set(s["registered_names"]) <= {v.name for v in views}


def test_registered_poses_and_similarity_between_two_gauges(sceaux_matches, tmp_path):
    views, feats, links = sceaux_matches
    db_path = colmap.write_database(tmp_path / "s.db", views, feats, links)
    calibrated = [v.name for v in views if colmap.calibrated(v)]
    assert len(calibrated) == 4  # K.txt
    rec = colmap.incremental_mapping(db_path, fixed_intrinsics=calibrated).reconstruction
    poses = colmap.registered_poses(rec)
    assert set(poses) <= {v.name for v in views} and len(poses) >= 3
    for name, (R, t, K) in poses.items():
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and t.shape == (3,)
        view = next(v for v in views if v.name == name)
        # the focal length kept (SIMPLE_RADIAL: one focal length sqrt(fx fy)), the principal
        # point too, back in the OpenCV pixel convention
        f = np.sqrt(view.K[0, 0] * view.K[1, 1])
        assert np.allclose(K[[0, 1], [0, 1]], f) and np.allclose(K[:2, 2], view.K[:2, 2])
    # the same model in another gauge: scale 3, a rotation about z, a shift
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    other = pycolmap.Reconstruction(rec)
    other.transform(pycolmap.Sim3d(3.0, pycolmap.Rotation3d(R), np.array([1.0, -2.0, 0.5])))
    M = colmap.similarity_between(rec, other)
    assert np.allclose(M[:, :3], 3.0 * R, atol=1e-6) and np.allclose(M[:, 3], [1, -2, 0.5], atol=1e-6)
    assert colmap.similarity_between(rec, pycolmap.Reconstruction()) is None


def test_incremental_mapping_without_verified_pairs_registers_nothing(tmp_path):
    views, feats = _views_and_features(n=2)
    path = colmap.write_database(tmp_path / "few.db", views, feats, Links([0], [1], [1], [2]))
    result = colmap.incremental_mapping(path)
    assert result.registered_images == 0 and result.points == 0


def test_colmap_log_quieted_inside_calls_only():
    """Regression: importing the triangulation module set pycolmap's log level for the
    whole process; the adapter now quiets COLMAP only inside its calls."""
    import importlib

    import pipeline.evaluation.triangulation

    before = pycolmap.logging.minloglevel
    importlib.reload(pipeline.evaluation.triangulation)
    assert pycolmap.logging.minloglevel == before
    with colmap.quiet_colmap(3):
        assert pycolmap.logging.minloglevel == max(before, 3)
    assert pycolmap.logging.minloglevel == before
