"""Tiny photo folders for the tests of what a folder holds: 40x30 noise images (the same
pixels on every machine, seed 0), each written in the format its name gives, or ``fmt``."""

from pathlib import Path

import numpy as np
from PIL import Image


def noise_photos(folder: Path, names, fmt: str | None = None) -> Path:
    """Write one 40x30 RGB noise image per name into ``folder`` (made if needed); ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    for name in names:
        Image.fromarray(rng.integers(0, 255, (30, 40, 3), dtype=np.uint8)).save(
            folder / name, format=fmt)
    return folder
