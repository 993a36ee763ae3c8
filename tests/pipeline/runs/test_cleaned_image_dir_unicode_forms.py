"""clean-db --image-dir where the database names 'château.jpg' with its accent decomposed
(NFD, as macOS wrote it) and the folder holds the file composed (NFC, unpacked elsewhere):
refused as "no image 'château.jpg' in it", a name printed like the file the folder visibly
held. The file is now found in either form, where only one file of the folder has it."""

import unicodedata

import numpy as np
from PIL import Image

from pipeline import colmap
from pipeline.__main__ import main
from pipeline.types import Features, Links, View

NAMES = ["château.jpg", "église.jpg", "b.jpg"]


def _db(path, names):
    rng = np.random.default_rng(0)
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    views = [View(n, np.zeros((240, 320, 3), np.uint8), K) for n in names]
    feats = [Features(rng.uniform([0, 0], [319, 239], (20, 2)).astype(np.float32),
                      np.zeros((20, 128), np.float32), np.ones(20, np.float32), "sift")
             for _ in names]
    rows = np.array([(0, r, 1, r) for r in range(10)] + [(1, r, 2, r) for r in range(10)]).T
    colmap.write_database(path, views, feats, Links(*rows))


def test_an_image_named_in_the_other_unicode_form_is_found(tmp_path, monkeypatch):
    import viz.rerun_log

    db = tmp_path / "in.db"
    _db(db, [unicodedata.normalize("NFD", n) for n in NAMES])
    images = tmp_path / "images"
    images.mkdir()
    for k, name in enumerate(NAMES):  # composed names on disk
        Image.new("L", (320, 240), 40 * (k + 1)).save(images / name)
    drawn = []
    monkeypatch.setattr(viz.rerun_log, "log_run",
                        lambda path, record, live=None: drawn.append(record))
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--image-dir",
                 str(images), "--quiet"]) == 0
    shades = {unicodedata.normalize("NFC", v.name): int(v.image.mean()) for v in drawn[0].views}
    assert shades == {"château.jpg": 40, "église.jpg": 80, "b.jpg": 120}
