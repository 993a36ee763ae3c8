"""``--geometry epipolar`` on a set where no image pair has a usable fundamental matrix (a
planar scene: every pair is a homography) guided nothing and said so only in a progress note
(hidden by --quiet); the run now warns that it was a descriptors-only run."""

import logging

import numpy as np
from PIL import Image

from pipeline.runs.landmarks import LandmarksConfig, guidance_warning, run_landmarks


def _planar_set(root, shift_px: float = 6.0):
    rng = np.random.default_rng(1)
    texture = (rng.random((160, 200)) * 255).astype(np.uint8)
    pts = rng.uniform(30, 120, (14, 2))
    data = root / "set"
    data.mkdir()
    for k in range(4):  # the same plane, translated: each pair is a homography
        Image.fromarray(np.roll(texture, int(shift_px) * k, axis=1)).save(data / f"v{k}.png")
        np.savetxt(data / f"v{k}.txt", pts + [shift_px * k, 0], fmt="%.2f")
    return data


def test_guidance_that_guided_no_pair_is_warned(tmp_path, caplog):
    data = _planar_set(tmp_path)
    config = LandmarksConfig(directory=str(data), geometry="epipolar", baselines=False,
                             out=str(tmp_path / "run"))
    with caplog.at_level(logging.WARNING):
        run_landmarks(config)
    assert "--geometry epipolar guided none of the 6 image pairs" in caplog.text


def test_the_warning_needs_every_pair_unguided():
    base = {"geometry": "epipolar", "edges": 6}
    assert guidance_warning({**base, "edges_without_model": 6})
    assert guidance_warning({**base, "edges_without_model": 5}) is None
    assert guidance_warning({"geometry": "none", "edges": 6, "edges_without_model": 0}) is None
    assert guidance_warning({**base, "edges": 0, "edges_without_model": 0}) is None
