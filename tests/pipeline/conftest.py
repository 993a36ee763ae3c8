"""Shared fixtures of the real-image tests (pipeline.io, pipeline.colmap, run-images, clean-db)."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

SCEAUX = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "sceaux_castle"
SCEAUX_IMAGES = ("100_7100.JPG", "100_7101.JPG", "100_7102.JPG", "100_7103.JPG")
SMALL_SIDE = 640


@pytest.fixture(scope="session")
def sceaux_small(tmp_path_factory) -> Path:
    """Four Sceaux photographs downscaled to 640 px, with a K.txt at that resolution.

    Made once per session. The K.txt is the data set's K scaled like the images (OpenCV pixel
    convention), so the folder looks like a full-resolution set to the code under test.
    """
    if not SCEAUX.is_dir():
        pytest.skip(f"Sceaux data set not found at {SCEAUX}")
    out = tmp_path_factory.mktemp("sceaux640")
    K = np.loadtxt(SCEAUX / "K.txt")
    for name in SCEAUX_IMAGES:
        with Image.open(SCEAUX / name) as im:
            w, h = im.size
            s = SMALL_SIDE / max(w, h)
            size = (round(w * s), round(h * s))
            im.convert("RGB").resize(size, Image.Resampling.LANCZOS).save(out / name, quality=95)
    sx, sy = size[0] / w, size[1] / h
    S = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1]])
    np.savetxt(out / "K.txt", S @ K, fmt="%.6f")
    return out
