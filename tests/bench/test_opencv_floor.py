"""``bench/opencv_floor.py`` run by hand: ``--help`` says what it measures, and no folder or a
folder without the rendered images is refused with an ``error:`` line and exit status 2
instead of a traceback (``make bench`` leaves it to ``bench/run_formation.py``)."""

from pathlib import Path

from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


def test_help_says_what_the_floor_measures(capsys):
    assert load_bench("opencv_floor").cli(["--help"]) == 0
    out = capsys.readouterr().out
    assert "IMAGE_DIR" in out and "OpenCV-only floor" in out


def test_no_folder_is_refused(capsys):
    assert load_bench("opencv_floor").cli([]) == 2
    err = capsys.readouterr().err
    assert "error: expected one IMAGE_DIR, got 0 arguments" in err and "Traceback" not in err


def test_a_folder_without_the_images_is_refused(tmp_path, capsys):
    (tmp_path / "K.txt").write_text("1 0 0\n0 1 0\n0 0 1\n")
    assert load_bench("opencv_floor").cli([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {tmp_path}: no cam*.png images with their K.txt")
