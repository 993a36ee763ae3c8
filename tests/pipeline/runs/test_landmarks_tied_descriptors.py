"""Landmarks labelled at one spot of an image get identical descriptors; the Hungarian
assignment cannot tell them apart and settles the tie by row order, which is the labels' order
in every image, so a run scored them as matched right by the matching alone. The run now warns
and names the image and the label rows."""

import logging

import numpy as np
from PIL import Image

from pipeline.runs.landmarks import LandmarksConfig, run_landmarks


def test_landmarks_at_one_spot_are_warned(tmp_path, caplog):
    rng = np.random.default_rng(0)
    texture = (rng.random((120, 160)) * 255).astype(np.uint8)
    pts = rng.uniform(30, 90, (6, 2))
    pts[4] = pts[1]  # rows 2 and 5 label one spot
    data = tmp_path / "set"
    data.mkdir()
    for k in range(3):
        Image.fromarray(np.roll(texture, 4 * k, axis=1)).save(data / f"v{k}.png")
        np.savetxt(data / f"v{k}.txt", pts + [4 * k, 0], fmt="%.2f")
    config = LandmarksConfig(directory=str(data), geometry="none", baselines=False,
                             out=str(tmp_path / "run"))
    with caplog.at_level(logging.WARNING):
        run_landmarks(config)
    text = caplog.text
    assert "3 image(s) hold landmarks with identical descriptors" in text
    assert "v0.png (2 landmarks, e.g. label rows 2 and 5)" in text
