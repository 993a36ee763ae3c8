"""run-images writes sparse/ and database.db at the resolution of each image file, also when
files of different sizes are downscaled to one size and one guessed K."""

import sqlite3
from pathlib import Path

import numpy as np
import pycolmap
from PIL import Image

from pipeline.__main__ import main

SCEAUX = Path(__file__).resolve().parents[2] / "data" / "sceaux_castle_640"
# three photographs of one aspect ratio saved at three sizes: --max-size 300 brings each to
# 300x225 with the same guessed K, which made them one camera, rescaled by one file's factor
SIZES = {"a.jpg": (320, 240), "b.jpg": (400, 300), "c.jpg": (600, 450)}
SOURCES = ("100_7100.JPG", "100_7102.JPG", "100_7103.JPG")


def test_files_of_different_sizes_keep_their_own_size_in_sparse_and_the_database(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for (name, size), source in zip(SIZES.items(), SOURCES, strict=True):
        Image.open(SCEAUX / source).resize(size, Image.LANCZOS).save(photos / name, quality=95)
    out = tmp_path / "run"
    assert main(["run-images", str(photos), "--max-size", "300", "--export-db", "--no-rerun",
                 "--no-fusion", "--out", str(out), "-q"]) == 0

    rec = pycolmap.Reconstruction(str(out / "sparse"))
    assert rec.num_reg_images() == 3
    for image in rec.images.values():
        cam = rec.cameras[image.camera_id]
        assert (cam.width, cam.height) == SIZES[image.name]
        xy = np.array([p.xy for p in image.points2D])
        assert np.all(xy.max(axis=0) <= SIZES[image.name])  # the points span the file
        assert xy[:, 0].max() > 0.8 * SIZES[image.name][0]

    db = sqlite3.connect(out / "database.db")
    sizes = {cid: (w, h) for cid, w, h in db.execute("SELECT camera_id, width, height FROM cameras")}
    for name, cid, image_id in db.execute("SELECT name, camera_id, image_id FROM images").fetchall():
        assert sizes[cid] == SIZES[name]
        rows, cols, data = db.execute("SELECT rows, cols, data FROM keypoints WHERE image_id = ?",
                                      (image_id,)).fetchone()
        kp = np.frombuffer(data, np.float32).reshape(rows, cols)[:, :2]
        assert np.all(kp.max(axis=0) <= SIZES[name])
        assert kp[:, 0].max() > 0.8 * SIZES[name][0]
    db.close()
