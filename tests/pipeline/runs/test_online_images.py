"""run-images DIR --sequence (pipeline.runs.online_images): a tiny folder of two robots'
frame sequences, associated online; the run folder's step list and tables."""

import csv
import json
import shutil
from pathlib import Path

import pytest

from pipeline.__main__ import main

SCEAUX = Path(__file__).parents[2] / "data" / "sceaux_castle_640"
FAST = ["--max-size", "200", "--features", "sift", "--max-features", "200",
        "--matcher", "opencv", "--graph", "complete"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("seq") / "team"
    files = sorted(SCEAUX.glob("*.JPG"))
    for robot, idx in (("a", [0, 2, 4]), ("b", [1, 3, 5])):
        (root / robot).mkdir(parents=True)
        for k, i in enumerate(idx):
            shutil.copy(files[i], root / robot / f"{k}.jpg")
    shutil.copy(SCEAUX / "K.txt", root / "K.txt")
    return root


@pytest.fixture(scope="module")
def run_dir(folder, tmp_path_factory):
    out = tmp_path_factory.mktemp("seqrun") / "run"
    assert main(["run-images", str(folder), "--sequence", "--window", "2", "--out", str(out),
                 *FAST]) == 0
    return out


def test_one_step_per_frame_index_and_conflict_free_after_each(run_dir):
    report = json.loads((run_dir / "report.json").read_text())
    assert [s["step"] for s in report["steps"]] == [0, 1, 2]
    assert report["n_robots"] == 2 and report["robots"] == ["a", "b"]
    assert report["n_images"] == 6 and report["window"] == 2
    for s in report["steps"]:
        for key in ("links_new", "conflictive_sets_after", "wall_s", "rounds", "bytes"):
            assert key in s
        assert s["conflictive_sets_after"] == 0
    assert report["conflict_free_every_step"] is True
    f = report["final"]
    assert sum(s["links_new"] for s in report["steps"]) == f["links"] > 0
    assert f["batch"]["conflictive_sets"] == 0
    assert report["steps"][-1]["batch"]["conflictive_sets_after"] == 0
    assert (run_dir / "recording.rrd").stat().st_size > 0


def test_images_and_links_tables(run_dir):
    with open(run_dir / "images.csv") as fh:
        images = list(csv.DictReader(fh))
    assert [(int(r["robot"]), int(r["step"]), r["name"]) for r in images] == [
        (0, 0, "a/0.jpg"), (1, 0, "b/0.jpg"), (0, 1, "a/1.jpg"), (1, 1, "b/1.jpg"),
        (0, 2, "a/2.jpg"), (1, 2, "b/2.jpg")]
    report = json.loads((run_dir / "report.json").read_text())
    with open(run_dir / "link_steps.csv") as fh:
        steps = list(csv.DictReader(fh))
    with open(run_dir / "links.csv") as fh:
        links = list(csv.DictReader(fh))
    assert len(steps) == len(links) == report["final"]["links"]
    for r in report["steps"]:
        assert sum(int(s["step_added"]) == r["step"] for s in steps) == r["links_new"]
    # a new link joins a frame of its step to a frame of the window (2 steps)
    step_of = {int(r["image"]): int(r["step"]) for r in images}
    for lk, s in zip(links, steps, strict=True):
        a, b = step_of[int(lk["cam_i"])], step_of[int(lk["cam_j"])]
        assert max(a, b) == int(s["step_added"]) and abs(a - b) < 2


@pytest.mark.parametrize("flags, match", [
    (["--export-db"], "--export-db is not available with --sequence"),
    (["--window", "0"], "--window 0: expected a number of steps >= 1"),
    (["--hold", "-1"], "--hold -1: expected a number of steps >= 0"),
    (["--remap"], "--remap is not available with --sequence"),
    (["--threads", "2"], "--threads is not available with --sequence"),
    (["--truth-tol", "3"], "--truth-tol is not available with --sequence"),
    # photo sequences never fuse: --no-fusion was accepted and changed nothing
    (["--no-fusion"], "--no-fusion is not available with --sequence (the online job fuses "
                      "nothing"),
])
def test_options_the_online_job_does_not_run_are_refused(folder, tmp_path, capsys, flags,
                                                         match):
    assert main(["run-images", str(folder), "--sequence", "--out", str(tmp_path / "x"), *FAST,
                 *flags]) == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_a_run_folder_inside_the_sequence_folder_is_refused(folder, capsys):
    """Every sub-folder of DIR is a robot: a run folder there would be one on the next run."""
    assert main(["run-images", str(folder), "--sequence", "--out", str(folder / "run"),
                 *FAST]) == 2
    assert "is inside DIR" in capsys.readouterr().err
    assert not (folder / "run").exists()


def test_the_merge_radius_reaches_the_robots_features(run_dir, folder, tmp_path):
    """--merge-radius is applied (it was once dropped): a wide radius merges keypoints, so
    fewer features and fewer links than the default's run."""
    out = tmp_path / "wide"
    assert main(["run-images", str(folder), "--sequence", "--window", "2", "--merge-radius",
                 "12", "--no-rerun", "--out", str(out), *FAST]) == 0
    wide, default = (json.loads((d / "report.json").read_text()) for d in (out, run_dir))
    assert wide["config"]["merge_radius"] == 12.0
    assert default["config"]["merge_radius"] is None
    assert wide["final"]["links"] < default["final"]["links"]


def test_the_hold_defaults_to_window_minus_one_and_is_a_choice(run_dir, folder, tmp_path):
    assert json.loads((run_dir / "report.json").read_text())["hold"] == 1  # --window 2
    out = tmp_path / "hold0"
    assert main(["run-images", str(folder), "--sequence", "--window", "2", "--hold", "0",
                 "--no-rerun", "--out", str(out), *FAST]) == 0
    assert json.loads((out / "report.json").read_text())["hold"] == 0


def test_a_graph_that_leaves_a_robot_alone_is_warned(tmp_path, capsys):
    """A graph file that never joins robot c: its frames match no one's; said, as run-images
    says it of a graph that splits the images."""
    files = sorted(SCEAUX.glob("*.JPG"))
    root = tmp_path / "team"
    for robot, idx in (("a", [0, 3]), ("b", [1, 4]), ("c", [2, 5])):
        (root / robot).mkdir(parents=True)
        for k, i in enumerate(idx):
            shutil.copy(files[i], root / robot / f"{k}.jpg")
    shutil.copy(SCEAUX / "K.txt", root / "K.txt")
    graph = tmp_path / "g.csv"
    graph.write_text("a,b\n")
    fast = [a for a in FAST if a not in ("--graph", "complete")]
    assert main(["run-images", str(root), "--sequence", "--graph", str(graph), "--no-rerun",
                 "--out", str(tmp_path / "run"), *fast]) == 0
    assert "splits the 3 robots into 2 groups" in capsys.readouterr().err


def test_names_with_commas_quotes_and_line_breaks_stay_one_row(tmp_path):
    """images.csv joined its fields with bare commas: a sub-folder 'rob,1' or a file
    'a\\nb.jpg' broke the row, so a CSV reader saw other frames and names."""
    files = sorted(SCEAUX.glob("*.JPG"))
    root = tmp_path / "team"
    names = {"rob,1": ['f 0,"x".jpg', 'f 1,"x".jpg'], 'r"2': ["a\nb0.jpg", "a\nb1.jpg"]}
    for (robot, frames), idx in zip(names.items(), ([0, 2], [1, 3]), strict=True):
        (root / robot).mkdir(parents=True)
        for name, i in zip(frames, idx, strict=True):
            shutil.copy(files[i], root / robot / name)
    out = tmp_path / "run"
    assert main(["run-images", str(root), "--sequence", "--no-rerun", "--out", str(out),
                 *FAST]) == 0
    with open(out / "images.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows == [["image", "robot", "step", "name"],
                    ["0", "0", "0", 'r"2/a\nb0.jpg'], ["1", "1", "0", 'rob,1/f 0,"x".jpg'],
                    ["2", "0", "1", 'r"2/a\nb1.jpg'], ["3", "1", "1", 'rob,1/f 1,"x".jpg']]


def test_a_knn_graph_with_sequence_is_refused_as_no_robot_graph(folder, tmp_path, capsys):
    """--sequence takes the robots' communication graph: knn:K (of unordered photos) was
    refused as needing 'the images' features', which the run had."""
    assert main(["run-images", str(folder), "--sequence", "--out", str(tmp_path / "x"), *FAST,
                 "--graph", "knn:1"]) == 2
    err = capsys.readouterr().err
    assert "graph 'knn:1': with --sequence the graph is the robots' communication graph" in err
    assert "seq:K" in err and "'robot_i,robot_j' lines" in err and "for unordered photos" in err
    assert "needs the images' features" not in err
    assert not (tmp_path / "x").exists()


def test_a_robot_folder_link_leading_nowhere_is_warned(folder, tmp_path, capsys):
    """A sub-folder that is a symbolic link to a drive not mounted was dropped from the team
    without a word: the run went on with one robot fewer."""
    root = tmp_path / "team"
    shutil.copytree(folder, root)
    (root / "c").symlink_to(tmp_path / "not-mounted")
    assert main(["run-images", str(root), "--sequence", "--no-rerun", "--quiet",
                 "--out", str(tmp_path / "run"), *FAST]) == 0
    err = capsys.readouterr().err
    assert "1 symbolic link(s) in " in err and "lead nowhere and are no robot (c)" in err


def test_frames_with_identical_pixels_are_warned(folder, tmp_path, capsys):
    """run-images warns the same photograph twice; with --sequence (a robot's folder copied
    as another's) it said nothing."""
    root = tmp_path / "team"
    shutil.copytree(folder, root)
    shutil.copytree(folder / "a", root / "c")
    assert main(["run-images", str(root), "--sequence", "--no-rerun", "--quiet",
                 "--out", str(tmp_path / "run"), *FAST]) == 0
    err = capsys.readouterr().err
    assert ("3 group(s) of frames have identical pixels (a/0.jpg = c/0.jpg; a/1.jpg = c/1.jpg; "
            "a/2.jpg = c/2.jpg)") in err


def test_a_frame_without_features_is_warned_and_in_the_report(folder, tmp_path, capsys):
    """A blank frame took no part without a word, where a batch run warns no-features."""
    import numpy as np
    from PIL import Image

    root = tmp_path / "team"
    shutil.copytree(folder, root)
    Image.fromarray(np.full((480, 640), 128, np.uint8)).save(root / "b" / "1.jpg")
    out = tmp_path / "run"
    assert main(["run-images", str(root), "--sequence", "--no-rerun", "--quiet",
                 "--out", str(out), *FAST]) == 0
    message = "no features found in 1 image(s): b/1.jpg (blank, too small or too narrow)"
    assert f"warning: {message}" in capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert report["features_per_camera"][3] == 0 and min(report["features_per_camera"][:3]) > 0
    assert [w["code"] for w in report["warnings"]] == ["no-features"]
    assert report["warnings"][0]["message"].startswith(message)


def test_opencv_sift_with_colmaps_matcher_finds_the_links_run_images_finds(folder, tmp_path):
    """--features sift with the default matcher (COLMAP's): the frames were extracted as a
    rendered formation's, plain SIFT, whose descriptors COLMAP's matcher saturates: no link
    at all. They are now extracted as run-images extracts photographs (RootSIFT, unit length)."""
    fast = [a for a in FAST if a not in ("--matcher", "opencv")]
    out = tmp_path / "colmap"
    assert main(["run-images", str(folder), "--sequence", "--window", "2", "--no-rerun",
                 "--quiet", "--out", str(out), *fast]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["config"]["matcher"] == "colmap"
    assert report["steps"][0]["links_new"] > 0
