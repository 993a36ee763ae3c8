"""A calibration saved as ``k.txt``, ``K.TXT`` or ``K.txt.txt`` (or a folder named K.txt) is
not the intrinsics file: run-images took the guessed focal length in its place without a
word, so a calibrated folder ran as an uncalibrated one. It is now warned, naming the file."""

import pytest
from noise_photos import noise_photos

from pipeline.inputs.photos import load_folder
from pipeline.inputs.sequence import load_sequence

K_TEXT = "50 0 19.5\n0 50 14.5\n0 0 1\n"


def _images(folder, names=("a.png", "b.png")):
    noise_photos(folder, names)


def _lookalike_warnings(caplog):
    return [r.getMessage() for r in caplog.records if "not read as the intrinsics" in r.getMessage()]


@pytest.mark.parametrize("name, what", [
    ("k.txt", "is not named exactly K.txt (letter case counts)"),
    ("K.TXT", "is not named exactly K.txt (letter case counts)"),
    ("K.txt.txt", "is not named exactly K.txt (letter case counts)"),
    ("K.txt", "is a folder"),
])
def test_a_k_txt_lookalike_is_warned(tmp_path, caplog, name, what):
    d = tmp_path / "photos"
    _images(d)
    if what == "is a folder":
        (d / name).mkdir()
    else:
        (d / name).write_text(K_TEXT)
    with caplog.at_level("WARNING", logger="pipeline"):
        views = load_folder(d, max_size=None)
    assert {v.intrinsics_source for v in views} == {"guess"}
    assert _lookalike_warnings(caplog) == [
        f"warning: {str(d / name)!r} {what}, so it is not read as the intrinsics file: the "
        "images' EXIF focal length or the guessed one serve instead; give the intrinsics as a "
        "file named exactly K.txt, or name the file with --intrinsics"]


def test_a_k_txt_is_not_warned(tmp_path, caplog):
    d = tmp_path / "photos"
    _images(d)
    (d / "K.txt").write_text(K_TEXT)
    with caplog.at_level("WARNING", logger="pipeline"):
        views = load_folder(d, max_size=None)
    assert {v.intrinsics_source for v in views} == {"K.txt"}
    assert _lookalike_warnings(caplog) == []


def test_a_robot_k_txt_lookalike_beside_the_teams_k_txt_is_warned(tmp_path, caplog):
    """With --sequence, DIR/K.txt serves the robots without one of their own; a robot's
    K.TXT gave way to it silently."""
    for robot in ("r0", "r1"):
        _images(tmp_path / robot, ("f0.png", "f1.png"))
    (tmp_path / "K.txt").write_text(K_TEXT)
    (tmp_path / "r1" / "K.TXT").write_text("60 0 19.5\n0 60 14.5\n0 0 1\n")
    with caplog.at_level("WARNING", logger="pipeline"):
        seq = load_sequence(tmp_path, max_size=None)
    assert {v.intrinsics_source for v in seq.views} == {"K.txt"}
    assert _lookalike_warnings(caplog) == [
        f"warning: {str(tmp_path / 'r1' / 'K.TXT')!r} is not named exactly K.txt (letter case "
        f"counts), so it is not read as the intrinsics file: {str(tmp_path / 'K.txt')!r} "
        "serves robot 'r1' instead; give the intrinsics as a file named exactly K.txt, or "
        "name the file with --intrinsics"]


def test_a_k_txt_that_is_a_fifo_is_named_as_such(tmp_path, caplog):
    """A K.txt that is a FIFO was read as absent (or, given with --intrinsics, said not to
    exist): it is named as what it is."""
    import os

    from pipeline.errors import InputError
    from pipeline.inputs.photos import read_k_txt

    d = tmp_path / "photos"
    _images(d)
    os.mkfifo(d / "K.txt")
    with caplog.at_level("WARNING", logger="pipeline"):
        load_folder(d, max_size=None)
    assert _lookalike_warnings(caplog) == [
        f"warning: {str(d / 'K.txt')!r} is not a regular file (a FIFO, device or socket), so it "
        "is not read as the intrinsics file: the images' EXIF focal length or the guessed one "
        "serve instead; give the intrinsics as a file named exactly K.txt, or name the file "
        "with --intrinsics"]
    with pytest.raises(InputError, match=r"^intrinsics file '.*K.txt' is not a regular file "
                                         r"\(a FIFO, device or socket\); give the K.txt file$"):
        read_k_txt(d / "K.txt")
    (tmp_path / "dead").symlink_to(tmp_path / "unmounted" / "K.txt")
    with pytest.raises(InputError, match=r"^intrinsics file '.*dead' is a symbolic link that "
                                         r"leads nowhere \(to '.*unmounted/K.txt'\)"):
        read_k_txt(tmp_path / "dead")
