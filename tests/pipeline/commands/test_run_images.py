"""run-images end to end on four downscaled Sceaux photographs; the run folder is checked against
itself (report.json vs links.csv vs database.db vs sparse/); each bad input fails cleanly."""

import csv
import json
import shutil

import numpy as np
import pycolmap
import pytest

from pipeline import colmap
from pipeline.__main__ import main
from pipeline.association import AssociationGraph, count_conflicts
from pipeline.types import Links


@pytest.fixture(scope="module")
def sceaux_run(sceaux_small, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "sceaux-complete"
    code = main(["run-images", str(sceaux_small), "--graph", "complete", "--max-size", "640",
                 "--features", "sift", "--export-db", "--out", str(out)])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return out, report, rows


def _links(rows, status=None):
    sel = [r for r in rows if status is None or r["status"] == status]
    cols = [np.array([int(r[k]) for r in sel], dtype=np.int64)
            for k in ("cam_i", "feat_i", "cam_j", "feat_j")]
    return Links(*cols)


def _link_set(links: Links):
    return set(zip(links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                   links.feat_j.tolist(), strict=True))


def test_run_folder_contract(sceaux_run):
    out, report, rows = sceaux_run
    for name in ("report.json", "links.csv", "sparse", "recording.rrd", "database.db"):
        assert (out / name).exists(), name
    assert (out / "recording.rrd").stat().st_size > 0
    for key in ("n_cameras", "comm_edges", "features_per_camera", "before", "after",
                "resolution", "fusion", "triangulation", "timings_s", "versions", "config"):
        assert key in report, key
    assert report["n_cameras"] == 4 and len(report["comm_edges"]) == 6
    assert [im["intrinsics_source"] for im in report["images"]] == ["K.txt"] * 4
    assert list(rows[0]) == ["cam_i", "feat_i", "cam_j", "feat_j", "status", "reason", "round",
                             "truth"]
    assert {r["truth"] for r in rows} == {""}  # no ground truth on real photographs
    assert {r["status"] for r in rows} <= {"kept", "deleted"}


def test_conflicts_after_cleaning_are_zero(sceaux_run):
    _, report, _ = sceaux_run
    assert report["after"]["conflictive_sets"] == 0
    assert report["after"]["conflictive_features"] == 0
    assert report["before"]["conflictive_sets"] >= report["after"]["conflictive_sets"]
    for name, baseline in report["baselines"].items():  # centralized references, same links
        assert baseline["conflictive_sets"] == 0, name


def test_report_recount_matches_links_csv(sceaux_run):
    _, report, rows = sceaux_run
    m = report["features_per_camera"]
    assert len(rows) == report["before"]["links"]
    before = count_conflicts(AssociationGraph(m, _links(rows))).as_dict()
    after = count_conflicts(AssociationGraph(m, _links(rows, "kept"))).as_dict()
    for key, value in before.items():
        assert report["before"][key] == value, key
    for key, value in after.items():
        assert report["after"][key] == value, key
    deleted = [r for r in rows if r["status"] == "deleted"]
    assert report["resolution"]["deleted_links"] == sum(r["reason"] == "resolution" for r in deleted)
    assert all(r["reason"] for r in deleted) and not any(r["reason"] for r in rows
                                                         if r["status"] == "kept")


def test_fusion_with_poses_of_the_first_reconstruction(sceaux_run):
    _, report, rows = sceaux_run
    fusion = report["fusion"]
    assert fusion["enabled"], fusion.get("reason")  # the 4 Sceaux images all register
    assert fusion["poses_from"] == "reconstruction before cleaning"
    registered = report["triangulation"]["before"]["registered_names"]
    assert fusion["cameras"] == len(registered)
    assert fusion["cut_links"] == sum(r["reason"] == "fusion-outlier" for r in rows)


def test_exported_database_holds_exactly_the_kept_links(sceaux_run):
    out, report, rows = sceaux_run
    contents = colmap.read_database(out / "database.db")
    # the database reader numbers images by sorted name, the run by content
    # (pipeline.inputs.photos.in_content_order): compare links by image name
    names = [im["name"] for im in report["images"]]
    assert sorted(contents.names) == sorted(names)

    def named(links, order):
        return {tuple(sorted(((order[a], b), (order[c], d)))) for a, b, c, d in _link_set(links)}

    assert named(contents.links, contents.names) == named(_links(rows, "kept"), names)
    with pycolmap.Database.open(out / "database.db") as db:
        assert db.num_matches() == len(rows)  # the raw matches table keeps every link
        assert db.num_images() == 4


def test_sparse_is_the_reconstruction_after_cleaning(sceaux_run):
    out, report, rows = sceaux_run
    rec = pycolmap.Reconstruction(out / "sparse")
    after = report["triangulation"]["after"]
    assert rec.num_reg_images() == after["registered_images"] >= 3
    assert rec.num_points3D() == after["points"] > 0
    assert 0 < after["mean_reprojection_error"] < 2.0
    assert report["triangulation"]["before"]["registered_images"] >= 3
    # made on the poses of the reconstruction before cleaning: no image it registered is lost
    assert any(r["status"] == "deleted" for r in rows)
    assert report["triangulation"]["after_from"].startswith("kept links triangulated on the poses")
    assert set(report["triangulation"]["before"]["registered_names"]) <= \
        set(after["registered_names"])


def test_remap_option_reaches_the_config():
    from pipeline.__main__ import build_parser
    from pipeline.commands.run_images import config_from_args

    parser = build_parser()
    argv = ["run-images", "DIR", "--graph", "ring"]
    assert config_from_args(parser.parse_args(argv)).remap is False
    assert config_from_args(parser.parse_args([*argv, "--remap"])).remap is True


def test_graph_defaults_to_complete():
    """Without --graph every pair is matched, as COLMAP's exhaustive matcher does."""
    from pipeline.__main__ import build_parser
    from pipeline.commands.run_images import config_from_args, sequence_config_from_args

    parser = build_parser()
    assert config_from_args(parser.parse_args(["run-images", "DIR"])).graph == "complete"
    args = parser.parse_args(["run-images", "DIR", "--sequence"])
    assert sequence_config_from_args(args).graph == "complete"


def test_mixed_sizes_and_guessed_intrinsics(tmp_path, sceaux_small):
    """An internet-style set: different sizes and aspect ratios, no K.txt, no EXIF."""
    from PIL import Image

    d = tmp_path / "mixed"
    d.mkdir()
    with Image.open(sceaux_small / "100_7100.JPG") as im:
        im.save(d / "a.png")
    with Image.open(sceaux_small / "100_7101.JPG") as im:
        im.resize((512, 385)).save(d / "b.jpg")
    with Image.open(sceaux_small / "100_7102.JPG") as im:
        im.crop((40, 0, 600, 481)).save(d / "c.tif")
    out = tmp_path / "run"
    assert main(["run-images", str(d), "--graph", "complete", "--no-rerun", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    # cameras in content order (pipeline.inputs.photos.in_content_order): compare by name
    images = {im["name"]: im for im in report["images"]}
    assert [images[n]["size"] for n in ("a.png", "b.jpg", "c.tif")] == \
        [[640, 481], [512, 385], [560, 481]]
    assert {im["intrinsics_source"] for im in report["images"]} == {"guess"}
    # each image its own guess: f = 1.2 * longest side
    assert [round(images[n]["K"][0][0], 3) for n in ("a.png", "b.jpg", "c.tif")] == \
        [768.0, 614.4, 672.0]
    assert report["after"]["conflictive_sets"] == 0
    assert report["before"]["links"] > 0


# ------------------------------------------------------------------------------------ bad input

def _fails(argv, out, capsys, match):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err, err
    assert not out.exists()  # nothing half-written
    assert not list(out.parent.glob(f".{out.name}*"))


def _copy(sceaux_small, dest, names):
    dest.mkdir()
    for n in names:
        shutil.copy(sceaux_small / n, dest / n)
    return dest


def test_empty_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    out = tmp_path / "run"
    _fails(["run-images", str(tmp_path / "empty"), "--graph", "ring", "--out", str(out)], out,
           capsys, "no images")


def test_one_image_only(tmp_path, sceaux_small, capsys):
    d = _copy(sceaux_small, tmp_path / "one", ["100_7100.JPG"])
    out = tmp_path / "run"
    _fails(["run-images", str(d), "--graph", "ring", "--out", str(out)], out, capsys,
           "only one image")


def test_non_image_file(tmp_path, sceaux_small, capsys):
    d = _copy(sceaux_small, tmp_path / "mixed", ["100_7100.JPG", "100_7101.JPG"])
    (d / "100_7102.JPG").write_text("not a photograph")
    out = tmp_path / "run"
    _fails(["run-images", str(d), "--graph", "ring", "--out", str(out)], out, capsys,
           "100_7102.JPG: cannot read it as an image")


def test_truncated_jpeg(tmp_path, sceaux_small, capsys):
    d = _copy(sceaux_small, tmp_path / "trunc", ["100_7100.JPG", "100_7101.JPG"])
    data = (d / "100_7101.JPG").read_bytes()
    (d / "100_7101.JPG").write_bytes(data[: len(data) // 3])
    out = tmp_path / "run"
    _fails(["run-images", str(d), "--graph", "ring", "--out", str(out)], out, capsys,
           "100_7101.JPG: cannot read it as an image")


def test_graph_file_naming_a_missing_image(tmp_path, sceaux_small, capsys):
    graph = tmp_path / "edges.txt"
    graph.write_text("100_7100.JPG,100_7101.JPG\n100_7101.JPG,100_7199.JPG\n")
    out = tmp_path / "run"
    _fails(["run-images", str(sceaux_small), "--graph", str(graph), "--out", str(out)], out,
           capsys, "line 2: image '100_7199.JPG' is not one of the 4 images")


def test_k_txt_that_does_not_parse(tmp_path, sceaux_small, capsys):
    k = tmp_path / "K.txt"
    k.write_text("fx 0 cx\n0 fy cy\n0 0 1\n")
    out = tmp_path / "run"
    _fails(["run-images", str(sceaux_small), "--graph", "ring", "--intrinsics", str(k),
            "--out", str(out)], out, capsys, "'fx' is not a number")


def test_unknown_feature_method(tmp_path, sceaux_small, capsys):
    out = tmp_path / "run"
    assert main(["run-images", str(sceaux_small), "--graph", "ring", "--features", "brief",
                 "--out", str(out)]) == 2
    assert "brief" in capsys.readouterr().err and not out.exists()


def test_bad_graph_kind(tmp_path, sceaux_small, capsys):
    out = tmp_path / "run"
    _fails(["run-images", str(sceaux_small), "--graph", "star", "--out", str(out)], out, capsys,
           "graph 'star'")


def test_help_lists_only_available_features_and_surf_fails_first(tmp_path, capsys):
    from pipeline.matching.features import available_methods, surf_available

    with pytest.raises(SystemExit):
        main(["run-images", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())  # argparse wraps at any width
    assert "|".join(available_methods()) in help_text
    assert ("surf" in help_text) == surf_available()
    assert "most similar" in help_text and "seq:K" in help_text  # what knn means
    if not surf_available():
        out = tmp_path / "run"
        assert main(["run-images", str(tmp_path / "no-such-dir"), "--graph", "ring",
                     "--features", "surf", "--out", str(out)]) == 2
        assert "surf" in capsys.readouterr().err and not out.exists()


def test_few_registered_images_are_flagged_in_report_and_on_stderr(tmp_path, sceaux_small,
                                                                   capsys):
    d = tmp_path / "six"
    d.mkdir()
    for name in sorted(p.name for p in sceaux_small.glob("*.JPG")):
        shutil.copy(sceaux_small / name, d / name)
    rng = np.random.default_rng(0)
    from PIL import Image

    for k in range(2):  # two images of nothing in common with the others
        Image.fromarray(rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)).save(d / f"z{k}.png")
    graph = tmp_path / "g.txt"
    graph.write_text("0,1\n2,3\n4,5\n")
    out = tmp_path / "run"
    assert main(["run-images", str(d), "--graph", str(graph), "--no-rerun",
                 "--out", str(out)]) == 0
    err = capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    flags = {f["flag"]: f for f in report["flags"]}
    assert "few-registered" in flags and "3 groups" in flags["few-registered"]["likely_cause"]
    assert "registered only" in err and "3 groups" in err
    # fusion never runs on a camera whose pose is unknown: no fusion cut touches one
    registered = set(report["triangulation"]["before"]["registered_names"])
    unposed = {k for k, im in enumerate(report["images"]) if im["name"] not in registered}
    assert unposed
    with open(out / "links.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["reason"] == "fusion-outlier":
                assert int(r["cam_i"]) not in unposed and int(r["cam_j"]) not in unposed
    fusion = report["fusion"]
    if fusion["enabled"]:
        assert set(fusion["cameras_without_pose"]) == {report["images"][k]["name"]
                                                       for k in unposed}


def test_sparse_is_at_the_resolution_of_the_files_with_one_shared_camera(tmp_path, sceaux_small):
    """Mapped at 320 px, sparse/ names the 640 px files: cameras and 2D points scaled back; one
    K.txt for all images is one camera; points take their colours from the images."""
    out = tmp_path / "run"
    assert main(["run-images", str(sceaux_small), "--graph", "complete", "--max-size", "320",
                 "--no-rerun", "--no-fusion", "--out", str(out)]) == 0
    rec = pycolmap.Reconstruction(out / "sparse")
    assert rec.num_cameras() == 1
    cam = next(iter(rec.cameras.values()))
    assert (cam.width, cam.height) == (640, 481)
    K = np.loadtxt(sceaux_small / "K.txt")
    assert np.allclose(cam.calibration_matrix()[0, 0], K[0, 0], rtol=1e-3)
    rec.update_point_3d_errors()
    assert 0 < rec.compute_mean_reprojection_error() < 2.0  # 2D points scaled with the camera
    xy = np.concatenate([[p.xy for p in rec.images[i].points2D] for i in rec.reg_image_ids()])
    assert xy[:, 0].max() > 330  # beyond the 320 px that was mapped
    colours = np.array([p.color for p in rec.points3D.values()])
    assert colours.std() > 0


def test_no_rerun_does_not_announce_a_recording(tmp_path, sceaux_small, capsys):
    out = tmp_path / "run"
    assert main(["run-images", str(sceaux_small), "--graph", "ring", "--max-size", "320",
                 "--no-rerun", "--no-fusion", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "run written to" in printed and "recording.rrd" not in printed.splitlines()[-1]
    assert not (out / "recording.rrd").exists()


def test_internet_style_photos_register_at_the_defaults(tmp_path, sceaux_small):
    """Shuffled random names, no K.txt, no EXIF: knn:2 by image similarity and the photo
    defaults register every image; the similarity graph is connected although the names are
    in random order."""
    from PIL import Image

    d = tmp_path / "internet"
    d.mkdir()
    rng = np.random.default_rng(7)
    names = sorted(p.name for p in sceaux_small.glob("*.JPG"))
    for name, new in zip(names, rng.permutation(len(names)), strict=True):
        with Image.open(sceaux_small / name) as im:
            Image.frombytes(im.mode, im.size, im.tobytes()).save(d / f"{9000 + new * 37}.png")
    out = tmp_path / "run"
    assert main(["run-images", str(d), "--graph", "knn:2", "--no-rerun", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert {im["intrinsics_source"] for im in report["images"]} == {"guess"}
    assert report["triangulation"]["before"]["registered_images"] == 4
    assert report["triangulation"]["after"]["registered_images"] == 4
    assert report["flags"] == []
    # the feature budget scaled with the 640x481 images: 2000, not the old cap's ~1600 left
    assert min(report["features_per_camera"]) > 1800


@pytest.mark.parametrize("graph", ["knn:2", "complete"])
def test_renaming_the_files_changes_no_decision(tmp_path, sceaux_small, graph):
    """The same photographs under random names, in another name order: camera k is the k-th
    image by content (pipeline.inputs.photos.in_content_order), so links.csv is byte for byte
    the same and the report differs only in the names."""
    renamed = tmp_path / "renamed"
    renamed.mkdir()
    shutil.copy(sceaux_small / "K.txt", renamed / "K.txt")
    names = sorted(p.name for p in sceaux_small.glob("*.JPG"))
    rng = np.random.default_rng(11)
    new_names = {n: f"{k:03d}.JPG" for n, k in zip(names, rng.permutation(900)[:len(names)],
                                                    strict=True)}
    for old, new in new_names.items():
        shutil.copy(sceaux_small / old, renamed / new)
    outs = []
    for folder, tag in ((sceaux_small, "named"), (renamed, "renamed")):
        out = tmp_path / f"run-{tag}"
        assert main(["run-images", str(folder), "--graph", graph, "--max-size", "320",
                     "--no-rerun", "--out", str(out)]) == 0
        outs.append(out)
    a, b = (json.loads((o / "report.json").read_text()) for o in outs)
    assert (outs[0] / "links.csv").read_bytes() == (outs[1] / "links.csv").read_bytes()
    assert [new_names[im["name"]] for im in a["images"]] == [im["name"] for im in b["images"]]
    assert a["comm_edges"] == b["comm_edges"]
    for when in ("before", "after"):
        ta, tb = a["triangulation"][when], b["triangulation"][when]
        assert (ta["registered_images"], ta["points"]) == (tb["registered_images"], tb["points"])


def test_cleaning_effect_names_the_stage_and_the_links(sceaux_run):
    """report.json's cleaning_effect: the points of the reconstruction before cleaning whose
    track held a cut link, by the stage that cut it, with those links' rows of links.csv."""
    _, report, rows = sceaux_run
    effect = report["cleaning_effect"]
    tri = report["triangulation"]
    assert effect["points_before"] == tri["before"]["points"]
    assert effect["points_after"] == tri["after"]["points"]
    cut_by = {}
    for r in rows:
        if r["reason"]:
            cut_by[r["reason"]] = cut_by.get(r["reason"], 0) + 1
    total_points = 0
    for stage, entry in effect["by_stage"].items():
        assert stage in cut_by and 0 < entry["count"] <= cut_by[stage]
        assert 0 < entry["points"] <= entry["count"]
        total_points += entry["points"]
        listed = entry["links_csv_rows"]
        assert len(listed) == min(entry["count"], 200)
        assert all(rows[k]["reason"] == stage and rows[k]["status"] == "deleted" for k in listed)
    assert effect["points_with_cut_links"] <= total_points
    lost = set(tri["before"]["registered_names"]) - set(tri["after"]["registered_names"])
    assert [e["image"] for e in effect["images_lost"]] == sorted(lost)
    gained = [e["image"] for e in effect["images_gained"]]
    assert (("images-gained" in {f["flag"] for f in report["flags"]}) == bool(gained))


@pytest.mark.parametrize("mode", [[], ["--sequence"]])
def test_a_bad_merge_radius_is_refused_before_the_photos_are_read(tmp_path, capsys, mode):
    """--merge-radius -1 was refused only after every photograph was loaded (and with a
    bad folder, the folder's error came first)."""
    missing = tmp_path / "not-yet-copied"
    assert main(["run-images", str(missing), *mode, "--merge-radius", "-1",
                 "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert "error: --merge-radius -1.0: expected pixels >= 0" in err
    assert "not-yet-copied" not in err and not (tmp_path / "run").exists()
