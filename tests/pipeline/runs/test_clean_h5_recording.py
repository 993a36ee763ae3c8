"""clean-h5 --image-dir: the recording draws hloc's keypoints where they are on the images.
hloc's keypoints are in the pixels of the image it read (its ``image_size``); they were
scaled by the image's size over the extent of its keypoints, and so drawn off their place."""

import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from PIL import Image

from pipeline.inputs.hloc import read_h5
from pipeline.runs.clean_h5 import clean_h5

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from test_clean_h5 import NAMES, _write  # noqa: E402

W, H = 400, 320  # the image files; _write's keypoints lie within 300 x 300


@pytest.mark.parametrize("image_size", [None, (2 * W, 2 * H)], ids=["not-stored", "stored"])
def test_keypoints_are_drawn_in_the_pixels_of_the_image(tmp_path, monkeypatch, image_size):
    import viz.rerun_log

    feats, matches = _write(tmp_path)
    if image_size is not None:  # the keypoints of an image twice the size of the files
        with h5py.File(feats, "a") as fd:
            for name in NAMES:
                fd[name].create_dataset("image_size", data=np.array(image_size))
    images = tmp_path / "images"
    for name in NAMES:
        (images / name).parent.mkdir(parents=True, exist_ok=True)
        Image.new("L", (W, H), 128).save(images / name, format="JPEG")
    drawn = []
    monkeypatch.setattr(viz.rerun_log, "log_run",
                        lambda path, record, live=None: drawn.append(record))
    clean_h5(feats, matches, tmp_path / "out.h5", image_dir=images)
    read = read_h5(feats, matches)
    scale = 1.0 if image_size is None else W / image_size[0]
    for kp, f, v in zip(read.keypoints, drawn[0].features, drawn[0].views, strict=True):
        assert v.size == (W, H)
        np.testing.assert_allclose(f.keypoints, (kp + 0.5) * scale - 0.5, atol=1e-4)
