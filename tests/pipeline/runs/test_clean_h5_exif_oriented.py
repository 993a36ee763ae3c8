"""clean-h5 --image-dir on photographs that carry an EXIF orientation tag (a phone's
portrait photo: landscape pixels stored, tag 6): hloc reads its images with OpenCV's
``imread``, which turns them by the tag, so its keypoints and its ``image_size`` are those of
the turned image. The recording drew the stored pixels under them (refused as "turned since
it was matched" where hloc stored the size); it now draws each image as hloc read it."""

import sys
from pathlib import Path

import cv2
import h5py
import numpy as np
import pytest
from PIL import Image

from pipeline.runs.clean_h5 import clean_h5

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from test_clean_h5 import NAMES, _write  # noqa: E402

W, H = 320, 240  # the pixels as stored; hloc's image is H x W where the tag turns them
ORIENTATION = {"a.jpg": 6, "sub/b.jpg": 8, "c.jpg": 1}  # two quarter turns, one as stored


@pytest.mark.parametrize("size_stored", [True, False], ids=["image_size", "no-image_size"])
def test_images_are_drawn_as_hloc_read_them(tmp_path, monkeypatch, size_stored):
    import viz.rerun_log

    feats, matches = _write(tmp_path)  # keypoints within 300 x 300
    if size_stored:
        with h5py.File(feats, "a") as fd:
            for name in NAMES:  # hloc's image_size: (width, height) of the image it read
                fd[name].create_dataset("image_size", data=np.array(
                    [H, W] if ORIENTATION[name] != 1 else [W, H]))
    images = tmp_path / "images"
    rng = np.random.default_rng(0)
    for name in NAMES:
        (images / name).parent.mkdir(parents=True, exist_ok=True)
        exif = Image.Exif()
        exif[0x0112] = ORIENTATION[name]
        Image.fromarray(rng.integers(0, 255, (H, W, 3), dtype=np.uint8)).save(
            images / name, exif=exif, quality=95)
    drawn = []
    monkeypatch.setattr(viz.rerun_log, "log_run",
                        lambda path, record, live=None: drawn.append(record))
    clean_h5(feats, matches, tmp_path / "out.h5", image_dir=images)
    assert sorted(v.name for v in drawn[0].views) == sorted(NAMES)
    for v in drawn[0].views:
        name = v.name
        as_hloc = cv2.imread(str(images / name), cv2.IMREAD_COLOR)[..., ::-1]  # hloc's read_image
        assert v.image.shape == as_hloc.shape, name
        np.testing.assert_array_equal(v.image, as_hloc)
