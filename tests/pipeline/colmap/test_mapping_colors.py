"""sparse/ of run-images is coloured from the image files in every format run-images reads:
COLMAP's own reader cannot read WebP and left every point of a WebP folder black."""

from pathlib import Path

import numpy as np
import pycolmap
from PIL import Image

from pipeline.__main__ import main

SCEAUX = Path(__file__).resolve().parents[2] / "data" / "sceaux_castle_640"
SOURCES = ("100_7100.JPG", "100_7101.JPG", "100_7102.JPG")


def _colours(folder: Path, suffix: str, tmp_path: Path) -> np.ndarray:
    out = tmp_path / f"run-{suffix}"
    assert main(["run-images", str(folder), "--max-size", "320", "--no-rerun", "--no-fusion",
                 "--out", str(out), "-q"]) == 0
    rec = pycolmap.Reconstruction(str(out / "sparse"))
    assert rec.num_points3D() > 100
    return np.array([rec.points3D[k].color for k in sorted(rec.points3D)], dtype=int)


def test_webp_photos_get_the_colours_of_their_png_twins(tmp_path):
    png, webp = tmp_path / "png", tmp_path / "webp"
    png.mkdir()
    webp.mkdir()
    for k, source in enumerate(SOURCES):
        im = Image.open(SCEAUX / source).convert("RGB").resize((320, 240), Image.LANCZOS)
        im.save(png / f"{k}.png")
        im.save(webp / f"{k}.webp", lossless=True)  # the same pixels
    from_png = _colours(png, "png", tmp_path)
    from_webp = _colours(webp, "webp", tmp_path)
    assert from_webp.max() > 0  # not black
    assert np.array_equal(from_webp, from_png)
