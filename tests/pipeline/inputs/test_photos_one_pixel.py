"""pipeline.inputs.photos: an image of fewer than 2 pixels on a side is refused with its size
and what to do."""

import numpy as np
import pytest
from PIL import Image

from pipeline.__main__ import main


@pytest.mark.parametrize("size", [(1, 1), (1, 40), (40, 1)])
def test_a_one_pixel_image_is_named_with_its_size_and_what_to_do(tmp_path, capsys, size):
    d = tmp_path / "imgs"
    d.mkdir()
    rng = np.random.default_rng(0)
    for k in range(2):
        Image.fromarray((rng.random((40, 50, 3)) * 255).astype(np.uint8)).save(d / f"p{k}.png")
    w, h = size
    Image.new("RGB", (w, h), (200, 10, 10)).save(d / "spacer.png")
    out = tmp_path / "run"
    assert main(["run-images", str(d), "--no-rerun", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if x.startswith("error:")]
    assert lines == [f"error: spacer.png: a {w}x{h} image (fewer than 2 pixels on a side) is no "
                     "photograph and holds no feature; remove or replace it"]
    assert "Traceback" not in err and not out.exists()
