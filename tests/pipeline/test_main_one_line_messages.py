"""Every error and warning is one line on stderr (README, "Errors you can meet"); a photo
whose file name holds a line break ('new\\nline.jpg') split them over two. The name is now
written with the break escaped."""

import logging

import numpy as np
from PIL import Image

from pipeline.__main__ import configure_logging, main


def test_an_error_naming_a_file_with_a_line_break_is_one_line(tmp_path, capsys):
    d = tmp_path / "photos"
    d.mkdir()
    Image.fromarray(np.zeros((8, 8), np.uint8)).save(d / "new\nline.png")
    assert main(["run-images", str(d), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: only one image in "), err
    assert "(new\\nline.png)" in err


def test_a_warning_naming_a_file_with_a_line_break_is_one_line(capsys):
    configure_logging(quiet=True)
    logging.getLogger("pipeline.runs.images").warning(
        "warning: %s", "images a.jpg, new\nline\t2.jpg have identical pixels")
    assert capsys.readouterr().err == (
        "warning: images a.jpg, new\\nline\\t2.jpg have identical pixels\n")


def test_progress_lines_and_other_scripts_are_as_they_were(capsys):
    configure_logging(quiet=False)
    logging.getLogger("pipeline.runs.images").info("[load] château 写真 ...")
    logging.getLogger("pipeline.runs.images").warning("warning: %s", "château 写真.jpg")
    assert capsys.readouterr().err == "[load] château 写真 ...\nwarning: château 写真.jpg\n"
