"""pipeline.colmap.mapping: the kept links of a database mapped on the poses of an earlier
reconstruction (mapping_from_poses), on four downscaled Sceaux photographs."""

import dataclasses

import numpy as np
import pycolmap
import pytest

from pipeline import colmap
from pipeline.association import AssociationGraph
from pipeline.errors import InputError


@pytest.fixture(scope="module")
def sceaux_before(sceaux_small, tmp_path_factory):
    """Views, features, links, the database of all links and its reconstruction."""
    from pipeline.commgraph import comm_graph
    from pipeline.inputs.photos import load_folder
    from pipeline.matching.features import extract_all
    from pipeline.matching.pairs import match_edges
    from pipeline.types import Links

    views = load_folder(sceaux_small, max_size=480)
    feats = extract_all(views, "sift", 1200)
    links = Links.from_matches(match_edges(feats, views,
                                           comm_graph("complete", [v.name for v in views])))
    work = tmp_path_factory.mktemp("poses")
    db = colmap.write_database(work / "before.db", views, feats, links)
    before = colmap.incremental_mapping(db, num_threads=1)
    assert before.registered_images == 4
    return views, feats, links, before, work


def _kept_database(sceaux_before, name, keep):
    views, feats, links, _, work = sceaux_before
    return colmap.write_database(work / name, views, feats, links, keep=keep)


def test_kept_links_on_the_poses_of_the_first_reconstruction(sceaux_before):
    """A third of the links cut: every image stays registered, near its first pose, and every
    point's track lies in one association set of the kept links (no cut link is used)."""
    views, feats, links, before, _ = sceaux_before
    keep = np.random.default_rng(3).random(len(links)) > 1 / 3
    db = _kept_database(sceaux_before, "third-cut.db", keep)
    after = colmap.mapping_from_poses(db, before.reconstruction, num_threads=1)
    assert after.registered_names == before.registered_names
    assert after.models == 1 and 0 < after.points < before.points
    assert after.mean_reprojection_error < 2.0
    # refined, not re-decided: the same gauge (two cameras held), centres close to before
    a, b = colmap.registered_poses(before.reconstruction), colmap.registered_poses(
        after.reconstruction)
    centres = {n: (-a[n][0].T @ a[n][1], -b[n][0].T @ b[n][1]) for n in a}
    spread = max(np.linalg.norm(c0 - c1) for c0, _ in centres.values()
                 for c1, _ in centres.values())
    assert max(np.linalg.norm(c0 - c1) for c0, c1 in centres.values()) < 0.05 * spread
    # the input reconstruction is left as it was
    assert before.reconstruction.num_points3D() == before.points
    # every track within one association set of the kept links
    m = np.array([len(f) for f in feats], dtype=np.int64)
    graph = AssociationGraph(m, links.subset(keep))
    labels = graph.components()
    camera = {v.name: k for k, v in enumerate(views)}
    rec = after.reconstruction
    for point in rec.points3D.values():
        sets = {labels[graph.offsets[camera[rec.images[el.image_id].name]] + el.point2D_idx]
                for el in point.track.elements}
        assert len(sets) == 1


def test_an_image_the_first_reconstruction_lacks_is_registered(sceaux_before):
    """The image left out of the start is offered to COLMAP's mapper, continuing the model."""
    _, _, links, before, _ = sceaux_before
    start = pycolmap.Reconstruction(before.reconstruction)
    left_out = start.images[start.reg_image_ids()[0]]
    start.deregister_frame(left_out.frame_id)
    assert start.num_reg_images() == 3
    db = _kept_database(sceaux_before, "all.db", np.ones(len(links), dtype=bool))
    after = colmap.mapping_from_poses(db, start, num_threads=1)
    assert after.registered_images == 4 and left_out.name in after.registered_names


def test_a_database_of_other_images_is_refused(sceaux_before, tmp_path):
    views, feats, links, before, _ = sceaux_before
    renamed = [dataclasses.replace(v, name=f"x{k}.png") for k, v in enumerate(views)]
    db = colmap.write_database(tmp_path / "other.db", renamed, feats, links)
    with pytest.raises(InputError, match="does not hold the reconstruction's image"):
        colmap.mapping_from_poses(db, before.reconstruction)


def test_without_a_start_it_maps_from_scratch(sceaux_before):
    _, _, links, _, _ = sceaux_before
    db = _kept_database(sceaux_before, "scratch.db", np.ones(len(links), dtype=bool))
    got = colmap.mapping_from_poses(db, None, num_threads=1)
    assert got.registered_images == 4 and got.points > 0


def test_a_start_with_a_bogus_camera_is_mapped_from_scratch(sceaux_before):
    """A camera COLMAP deems bogus (a distortion term above 1) would make its triangulator skip
    every image of it: no points. Such a start is refused and the database mapped afresh."""
    _, _, links, before, _ = sceaux_before
    start = pycolmap.Reconstruction(before.reconstruction)
    assert colmap.poses_usable(start)
    for camera in start.cameras.values():
        params = np.array(camera.params)
        params[-1] = -1.07  # SIMPLE_RADIAL's k, as left by one mapping of the AABB ring
        camera.params = params
    assert not colmap.poses_usable(start) and not colmap.poses_usable(None)
    db = _kept_database(sceaux_before, "bogus.db", np.ones(len(links), dtype=bool))
    got = colmap.mapping_from_poses(db, start, num_threads=1)
    assert got.registered_images == 4 and got.points > 0


def _fake(registered_by_threshold, n=6):
    """A mapping function registering ``registered_by_threshold[t]`` of ``n`` images at
    threshold ``t``; the thresholds it was called with, in order."""
    calls = []

    def mapping(database_path, *, min_pose_inliers, **options):
        calls.append((min_pose_inliers, options))
        k = registered_by_threshold[min_pose_inliers]
        return colmap.MappingSummary(n, 1, k, [f"{i}.png" for i in range(k)], 10 * k, 30 * k,
                                     3.0, 0.5, None, min_pose_inliers)
    return mapping, calls


def test_retry_only_when_images_are_missing():
    """COLMAP's threshold first; every image registered: no second mapping."""
    from pipeline.colmap.mapping import COLMAP_MIN_POSE_INLIERS, RETRY_MIN_POSE_INLIERS

    mapping, calls = _fake({COLMAP_MIN_POSE_INLIERS: 6, RETRY_MIN_POSE_INLIERS: 6})
    out = colmap.incremental_mapping_with_retry("db", mapping=mapping, num_threads=1)
    assert [c[0] for c in calls] == [COLMAP_MIN_POSE_INLIERS]
    assert calls[0][1] == {"num_threads": 1}
    assert out.min_pose_inliers == COLMAP_MIN_POSE_INLIERS
    assert out.registered_at_colmap_default is None
    assert "registered_at_colmap_default" not in out.summary()


def test_retry_kept_only_when_it_registers_more():
    from pipeline.colmap.mapping import COLMAP_MIN_POSE_INLIERS, RETRY_MIN_POSE_INLIERS

    mapping, calls = _fake({COLMAP_MIN_POSE_INLIERS: 2, RETRY_MIN_POSE_INLIERS: 6})
    out = colmap.incremental_mapping_with_retry("db", mapping=mapping)
    assert [c[0] for c in calls] == [COLMAP_MIN_POSE_INLIERS, RETRY_MIN_POSE_INLIERS]
    assert out.registered_images == 6 and out.min_pose_inliers == RETRY_MIN_POSE_INLIERS
    assert out.summary()["registered_at_colmap_default"] == 2
    # a retry that registers no more: the first model stays
    mapping, _ = _fake({COLMAP_MIN_POSE_INLIERS: 3, RETRY_MIN_POSE_INLIERS: 3})
    out = colmap.incremental_mapping_with_retry("db", mapping=mapping)
    assert out.min_pose_inliers == COLMAP_MIN_POSE_INLIERS and out.registered_images == 3


def test_the_threshold_reaches_colmaps_mapper(sceaux_before):
    """The threshold is the mapper's ``abs_pose_min_num_inliers``, and the summary names it."""
    from pipeline.colmap.mapping import _pipeline_options

    *_, work = sceaux_before
    db = _kept_database(sceaux_before, "threshold.db", None)
    options, _, _ = _pipeline_options(db, 1, 0, (), "", 15)
    assert options.mapper.abs_pose_min_num_inliers == 15
    out = colmap.incremental_mapping(db, num_threads=1, min_pose_inliers=15)
    assert out.summary()["min_pose_inliers"] == 15 and out.registered_images == 4


def test_a_database_rescaled_to_the_files(sceaux_before, tmp_path):
    """rescale_database (run-images --export-db): cameras at the files' size, keypoints and
    two-view geometries scaled alike, so every kept match satisfies the scaled F as it did the
    original (x_jᵀ F x_i is invariant), matches and inliers unchanged."""
    import shutil

    views, feats, links, _, _ = sceaux_before
    db = _kept_database(sceaux_before, "scaled-src.db", None)
    out = tmp_path / "scaled.db"
    shutil.copyfile(db, out)
    sizes = {v.name: (3 * v.size[0], 2 * v.size[1]) for v in views}  # sx = 3, sy = 2
    colmap.rescale_database(out, sizes)

    def read(path):
        with pycolmap.Database.open(str(path)) as d:
            ims = {im.image_id: im for im in d.read_all_images()}
            cams = {c.camera_id: c for c in d.read_all_cameras()}
            kps = {i: np.array(d.read_keypoints(i)) for i in ims}
            pids, geoms = d.read_two_view_geometries()
            return ims, cams, kps, dict(zip(pids, geoms, strict=True)), d.num_matches()

    ims0, cams0, kp0, g0, n0 = read(db)
    ims1, cams1, kp1, g1, n1 = read(out)
    assert n1 == n0 and g0.keys() == g1.keys()
    for i, im in ims1.items():
        cam = cams1[im.camera_id]
        assert (cam.width, cam.height) == sizes[im.name]
        np.testing.assert_allclose(kp1[i][:, 0], 3 * kp0[i][:, 0], rtol=1e-6)
        np.testing.assert_allclose(kp1[i][:, 1], 2 * kp0[i][:, 1], rtol=1e-6)
        f0, f1 = cams0[ims0[i].camera_id].focal_length, cam.focal_length
        assert 2 * f0 < f1 < 3 * f0  # one focal length, scaled between sy and sx
    checked = 0
    for pid, g in g1.items():
        i, j = pycolmap.pair_id_to_image_pair(pid)
        inl = np.asarray(g.inlier_matches)
        assert np.array_equal(inl, np.asarray(g0[pid].inlier_matches))
        if not len(inl) or g0[pid].F is None:
            continue

        def residual(kp, F, i=i, j=j, inl=inl):
            a = np.c_[kp[i][inl[:, 0], :2], np.ones(len(inl))]
            b = np.c_[kp[j][inl[:, 1], :2], np.ones(len(inl))]
            return np.einsum("ni,ij,nj->n", b, F, a)

        r0, r1 = residual(kp0, np.asarray(g0[pid].F)), residual(kp1, np.asarray(g1[pid].F))
        # keypoints are stored as float32: the residuals agree to its precision
        np.testing.assert_allclose(r1, r0, atol=1e-4 * np.abs(r0).max() + 1e-9)
        checked += 1
    assert checked > 0


def _poses(centres):
    """registered_poses-like ``{name: (R, t, K)}`` of cameras at ``centres``."""
    return {f"im{k}": (np.eye(3), -np.asarray(c, float), np.eye(3))
            for k, c in enumerate(centres)}


@pytest.mark.parametrize("centres", [
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0]],                 # three centres, centred by the mapper
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]],     # a plane through the origin
    [[1, 2, 3], [4, 5, 6], [7, 8, 10], [0, 1, -2]],
])
def test_similarity_between_centres_on_a_plane_through_the_origin(monkeypatch, centres):
    """Three registered images (run-images on three photos, the reconstruction centred on
    them) gave None (pycolmap.estimate_sim3d refuses such centres), and the fused points
    were left out of recording.rrd while report.json counted them."""
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    src = np.asarray(centres, float)
    tgt = 3.0 * src @ R.T + [1.0, -2.0, 0.5]
    poses = {"src": _poses(src), "tgt": _poses(tgt)}
    monkeypatch.setattr("pipeline.colmap.mapping.registered_poses", lambda rec: poses[rec])
    M = colmap.similarity_between("src", "tgt")
    assert M is not None
    assert np.allclose(M[:, :3], 3.0 * R, atol=1e-9) and np.allclose(M[:, 3], [1, -2, 0.5],
                                                                       atol=1e-9)
    assert np.allclose(colmap.similarity_between("src", "src"), np.eye(3, 4), atol=1e-9)


def test_similarity_between_collinear_centres_is_unknown(monkeypatch):
    poses = _poses([[0, 0, 0], [1, 1, 1], [2, 2, 2]])
    monkeypatch.setattr("pipeline.colmap.mapping.registered_poses", lambda rec: poses)
    assert colmap.similarity_between("a", "b") is None
