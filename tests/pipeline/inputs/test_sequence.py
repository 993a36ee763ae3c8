"""Per-robot frame sequences (pipeline.inputs.sequence): robots and steps in name order,
one intrinsics file for all, clear errors on a bad folder."""

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.inputs.sequence import load_sequence

SCEAUX = Path(__file__).parents[2] / "data" / "sceaux_castle_640"


def _folder(root: Path, frames: dict) -> Path:
    files = sorted(SCEAUX.glob("*.JPG"))
    for robot, idx in frames.items():
        (root / robot).mkdir(parents=True)
        for k, i in enumerate(idx):
            shutil.copy(files[i], root / robot / f"f{k:02d}.jpg")
    shutil.copy(SCEAUX / "K.txt", root / "K.txt")
    return root


def test_step_k_is_every_robots_kth_frame(tmp_path):
    root = _folder(tmp_path / "seq", {"r1": [1, 3], "r0": [0, 2], ".hidden": [5, 6]})
    seq = load_sequence(root, max_size=64)
    assert seq.robots == ["r0", "r1"] and seq.steps == 2 and seq.n_robots == 2
    assert [v.name for v in seq.views] == ["r0/f00.jpg", "r1/f00.jpg", "r0/f01.jpg",
                                           "r1/f01.jpg"]
    assert {v.intrinsics_source for v in seq.views} == {"K.txt"}
    assert max(seq.views[0].size) == 64


def test_a_robots_own_k_txt_is_not_overridden_by_the_teams(tmp_path):
    """With a DIR/K.txt, a sub-folder's own K.txt (another camera) was ignored without a
    word: that robot's frames got the team's focal length."""
    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    (root / "b" / "K.txt").write_text("500 0 300\n0 500 200\n0 0 1\n")
    seq = load_sequence(root, max_size=None)
    team = np.loadtxt(SCEAUX / "K.txt")
    for v in seq.views:
        want = np.array([[500.0, 0, 300], [0, 500, 200], [0, 0, 1]]) \
            if v.name.startswith("b/") else team
        np.testing.assert_allclose(v.K, want, err_msg=v.name)


def test_a_bad_frame_names_its_robot(tmp_path):
    """Robots' frames often share names (f00.jpg in every sub-folder): an error naming the
    file alone did not say which robot's it was."""
    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    (root / "b" / "f01.jpg").write_bytes(b"")
    with pytest.raises(InputError, match=r"^robot 'b' \(.*seq/b'\): f01\.jpg: the file is empty"):
        load_sequence(root, max_size=64)


def test_robot_folder_names_that_are_not_utf8_are_refused(tmp_path):
    """A Latin-1 sub-folder name crashed the run with a traceback where images.csv was
    written."""
    import os

    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    (root / "b").rename(root / os.fsdecode(b"rob\xe9"))
    with pytest.raises(InputError, match=r"1 robot sub-folder name\(s\) are not UTF-8 text "
                                         r"\('rob\\udce9'\)"):
        load_sequence(root, max_size=64)


def test_robots_with_different_numbers_of_frames_are_refused(tmp_path):
    root = _folder(tmp_path / "seq", {"a": [0, 1, 2], "b": [3, 4]})
    with pytest.raises(InputError, match=r"different numbers of frames \(a: 3, b: 2\)"):
        load_sequence(root, max_size=64)
    # the README's errors table has its row (it had none), with what to do
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[3] / "README.md").read_text()
    errors = readme[readme.index("## Errors you can meet"):readme.index("## Layout")]
    row = next((r for r in errors.splitlines()
                if "robots hold different numbers of frames" in r), None)
    assert row is not None and "the same number of frames" in row and row.endswith("| 2 |")


def test_a_sub_folder_without_images_is_no_robot(tmp_path):
    """E.g. a run folder written into DIR: skipped and listed, not a robot of 0 frames."""
    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    (root / "run" / "sparse").mkdir(parents=True)
    (root / "run" / "report.json").write_text("{}")
    seq = load_sequence(root, max_size=64)
    assert seq.robots == ["a", "b"] and seq.empty == ["run"] and seq.steps == 2


def test_a_team_needs_two_robot_folders(tmp_path):
    root = _folder(tmp_path / "seq", {"a": [0, 1]})
    with pytest.raises(InputError, match="1 robot sub-folder"):
        load_sequence(root, max_size=64)
    with pytest.raises(InputError, match="one sub-folder of frames per robot"):
        load_sequence(tmp_path / "missing")


def test_one_frame_per_robot_is_one_step_not_a_sequence(tmp_path):
    root = _folder(tmp_path / "seq", {"a": [0], "b": [1]})
    with pytest.raises(InputError, match="every robot holds one frame .* drop --sequence"):
        load_sequence(root, max_size=64)
    # a robot with one frame among robots with more: the counts are named, not its folder
    root = _folder(tmp_path / "seq2", {"a": [0], "b": [1, 2]})
    with pytest.raises(InputError, match=r"different numbers of frames \(a: 1, b: 2\)"):
        load_sequence(root, max_size=64)


def test_a_sequence_folder_without_sequence_says_to_add_it(tmp_path):
    from pipeline.inputs.photos import load_folder

    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    with pytest.raises(InputError, match="holds 2 sub-folder.*add --sequence"):
        load_folder(root, max_size=64)


def test_images_beside_the_robot_folders_are_named_as_unused(tmp_path):
    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    assert load_sequence(root, max_size=64).ignored == []
    shutil.copy(sorted(SCEAUX.glob("*.JPG"))[4], root / "stray.jpg")
    seq = load_sequence(root, max_size=64)
    assert seq.ignored == ["stray.jpg"] and len(seq.views) == 4


def test_names_that_sort_otherwise_by_number_are_warned(tmp_path, caplog):
    """frame10 sorts before frame2 by name: step 1 was every robot's tenth frame, without a
    word; robots robot10 / robot2 put line and ring out of number order alike."""
    files = sorted(SCEAUX.glob("*.JPG"))
    root = tmp_path / "seq"
    for robot, idx in (("robot2", [0, 2, 4]), ("robot10", [1, 3, 5])):
        (root / robot).mkdir(parents=True)
        for name, i in zip(("frame1.jpg", "frame2.jpg", "frame10.jpg"), idx, strict=True):
            shutil.copy(files[i], root / robot / name)
    with caplog.at_level("WARNING"):
        seq = load_sequence(root, max_size=64)
    assert seq.robots == ["robot10", "robot2"]  # name order, as documented
    assert [v.name for v in seq.views[:4]] == ["robot10/frame1.jpg", "robot2/frame1.jpg",
                                               "robot10/frame10.jpg", "robot2/frame10.jpg"]
    text = caplog.text
    assert "robot sub-folders sort by name otherwise than by number (robot10 before robot2)" \
        in text and "robot002" in text
    assert ("2 robot(s) (robot10, robot2) hold frames that sort by name otherwise than by "
            "number (robot10/frame10.jpg before robot10/frame2.jpg)") in text
    caplog.clear()
    with caplog.at_level("WARNING"):
        load_sequence(_folder(tmp_path / "padded", {"r1": [0, 1], "r2": [2, 3]}), max_size=64)
    assert "by number" not in caplog.text


def test_a_robot_folder_of_frames_in_a_format_not_read_says_why_it_is_no_robot(tmp_path,
                                                                                caplog):
    """A sub-folder of GIF frames was only said to 'hold no image': the robot was dropped
    without naming the files left out, as run-images names them in a flat folder."""
    from PIL import Image

    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    (root / "c").mkdir()
    for k in range(2):
        Image.new("L", (64, 48), 90).save(root / "c" / f"f{k}.gif")
    with caplog.at_level("WARNING"):
        seq = load_sequence(root, max_size=64)
    assert seq.robots == ["a", "b"] and seq.empty == ["c"]
    assert "c': 2 image file(s) of a format not read here left out (f0.gif, f1.gif" \
        in caplog.text


def test_a_robot_folder_holding_robot_folders_does_not_suggest_sequence(tmp_path, caplog):
    """A sub-folder holding a folder of frames was warned '... one sub-folder of frames per
    robot is --sequence' while --sequence was given: the hint now says where a robot's frames
    must lie."""
    root = _folder(tmp_path / "seq", {"a": [0, 1], "b": [2, 3]})
    _folder(root / "group", {"r5": [4, 5]})
    with caplog.at_level("WARNING"):
        seq = load_sequence(root, max_size=64)
    assert seq.empty == ["group"]
    assert "1 sub-folder(s) holding images left out (r5; a robot's frames lie directly in " \
           "its own sub-folder of the --sequence folder)" in caplog.text
    assert "is --sequence" not in caplog.text
