"""run-images: report.json's config records merge_radius_used_px, the radius the keypoints
were merged at, as run-formation's does; with --features sift and no --merge-radius the config
said merge_radius null and nothing of the rule's 2 px the run merged at."""

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipeline.__main__ import main

DATA = Path(__file__).resolve().parents[2] / "data" / "graffiti_small"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("photos")
    for k in (1, 2, 3):  # three small copies: a fast run
        im = Image.open(DATA / f"img{k}.png").convert("L")
        im.resize((im.width // 2, im.height // 2)).save(out / f"img{k}.png")
    return out


@pytest.mark.parametrize("extra,used", [
    ([], 2.0),                                      # the evidence rule's own radius
    (["--resolution", "paper"], None),              # the co-location radius of Alg. 1
    (["--merge-radius", "1.5"], 1.5),
])
def test_the_radius_used_is_recorded(folder, tmp_path, extra, used):
    from pipeline.matching.features import MERGE_RADIUS_PX

    out = tmp_path / "run"
    assert main(["run-images", str(folder), "--features", "sift", "--max-features", "300",
                 "--no-rerun", "--no-fusion", "-q", "--out", str(out), *extra]) == 0
    config = json.loads((out / "report.json").read_text())["config"]
    want = MERGE_RADIUS_PX if used is None else used
    assert np.isclose(config["merge_radius_used_px"], want, rtol=0, atol=1e-12)
