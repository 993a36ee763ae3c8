"""clean-db / clean-h5 --image-dir: an image whose shape is not that of the image its
keypoints are in (turned a quarter since it was matched, another photograph of that name)
had its keypoints scaled by each axis apart and drawn stretched over the wrong pixels,
without a word. It is now refused before any work, naming the image and both sizes; a
copy scaled alike on both axes is still drawn."""

import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from PIL import Image

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import refused  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402
from test_clean_h5 import NAMES, _write  # noqa: E402


@pytest.fixture(scope="module")
def source_db(tmp_path_factory):
    path = tmp_path_factory.mktemp("db") / "in.db"
    _db_with_planted_conflicts(path)  # four 320 x 240 cameras, view_0.jpg .. view_3.jpg
    return path


def _images(folder, sizes):
    folder.mkdir()
    for name, size in sizes.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        Image.new("L", size, 128).save(folder / name, format="JPEG")


@pytest.mark.parametrize("size, turned", [((240, 320), True), ((320, 100), False)],
                         ids=["turned", "other-shape"])
def test_an_image_of_another_shape_is_refused(source_db, tmp_path, capsys, size, turned):
    images = tmp_path / "images"
    _images(images, {f"view_{k}.jpg": size if k == 2 else (320, 240) for k in range(4)})
    line = refused(capsys, ["clean-db", str(source_db), "--out", str(tmp_path / "o.db"),
                            "--image-dir", str(images)], tmp_path,
                   f"--image-dir {str(images)!r}: 'view_2.jpg' is {size[0]}x{size[1]}, but "
                   "its keypoints are in a 320x240 image (the camera of the database), and it "
                   "is not that image scaled")
    assert ("turned a quarter" in line) == turned


def test_copies_scaled_alike_on_both_axes_are_drawn(source_db, tmp_path, capsys):
    images = tmp_path / "images"
    _images(images, {f"view_{k}.jpg": (161, 120) for k in range(4)})  # 320 x 240 halved, rounded
    assert main(["clean-db", str(source_db), "--out", str(tmp_path / "o.db"),
                 "--image-dir", str(images)]) == 0


def test_clean_h5_refuses_an_image_of_another_shape_than_its_image_size(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    with h5py.File(feats, "a") as fd:
        for name in NAMES:
            fd[name].create_dataset("image_size", data=np.array([400, 320]))
    images = tmp_path / "images"
    _images(images, {name: (320, 400) if name == "c.jpg" else (400, 320) for name in NAMES})
    refused(capsys, ["clean-h5", "--features", str(feats), "--matches", str(matches),
                     "--out", str(tmp_path / "o.h5"), "--image-dir", str(images)], tmp_path,
            "'c.jpg' is 320x400, but its keypoints are in a 400x320 image (hloc's image_size "
            "in the features file)", "turned a quarter")


def test_names_without_sizes_check_the_files_only(tmp_path):
    """check_image_dir with names and no sizes (the sizes are optional): a zip against an empty
    list raised ValueError ('zip() argument 2 is shorter than argument 1')."""
    from pipeline.runs.cleaned import check_image_dir

    _images(tmp_path / "images", {"a.jpg": (40, 30)})
    check_image_dir(tmp_path / "images", ["a.jpg"])
