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
