"""run-images on a folder where some photos show another scene: the images the reconstruction
left unregistered are named in the report's flags and on stderr (more than half registered,
so no flag said anything before)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT / "tests" / "data"


def test_photos_of_another_scene_are_named_as_unregistered(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for k in range(5):
        shutil.copy(DATA / "sceaux_castle_640" / f"100_710{k}.JPG", photos)
    for k in (1, 2):  # a planar poster: no model starts from it, nor joins the castle's
        shutil.copy(DATA / "graffiti_small" / f"img{k}.png", photos)
    out = subprocess.run([sys.executable, "-m", "pipeline", "run-images", str(photos), "-q",
                          "--no-rerun", "--no-fusion", "--max-size", "400",
                          "--out", str(tmp_path / "run")], cwd=ROOT, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    flags = json.loads((tmp_path / "run" / "report.json").read_text())["flags"]
    left = [f for f in flags if f["flag"] == "unregistered"]
    assert left and left[0]["message"] == ("the reconstruction left 2 of 7 images "
                                           "unregistered: img1.png, img2.png")
    assert "left 2 of 7 images unregistered" in out.stderr
