"""clean-db refuses keypoints that are no position in their camera's image, naming the image.

NaN keypoints were refused later as ``keypoints of camera 0: a non-finite value`` (the
pipeline's index, not the image); keypoints of another resolution than their camera were read
as they were, and with ``1e30`` ones ``--fusion``'s mapping never returned.
"""

import hashlib
import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import one_line_error  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


def _set_keypoints(db, name, change):
    con = sqlite3.connect(db)
    image_id = con.execute("SELECT image_id FROM images WHERE name = ?", (name,)).fetchone()[0]
    rows, cols, data = con.execute("SELECT rows, cols, data FROM keypoints WHERE image_id = ?",
                                   (image_id,)).fetchone()
    kp = np.frombuffer(data, np.float32).reshape(rows, cols).copy()
    change(kp)
    con.execute("UPDATE keypoints SET data = ? WHERE image_id = ?", (kp.tobytes(), image_id))
    con.commit()
    con.close()


def _nan(kp):
    kp[3, :2] = np.nan


def _huge(kp):
    kp[:, :2] = 1e30


def _twice_the_resolution(kp):
    kp[:, :2] *= 2


@pytest.mark.parametrize("change,needle", [
    (_nan, "keypoint 3 of image 'view_1.jpg' is [nan, nan], not a position"),
    (_huge, "keypoint 0 of image 'view_1.jpg' at [1e+30, 1e+30] lies outside the 320x240 "
            "image of its camera (30 of its 30 keypoints do)"),
    (_twice_the_resolution, "of image 'view_1.jpg' at ["),
])
def test_keypoints_outside_the_image_are_refused(tmp_path, capsys, change, needle):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    _set_keypoints(db, "view_1.jpg", change)
    digest = hashlib.sha256(db.read_bytes()).hexdigest()
    out = tmp_path / "o.db"
    assert main(["clean-db", str(db), "--out", str(out), "--no-rerun"]) == 2
    line = one_line_error(capsys, f"database {str(db)!r}", needle)
    if change is _twice_the_resolution:
        assert "lies outside the 320x240 image of its camera" in line
    assert hashlib.sha256(db.read_bytes()).hexdigest() == digest
    assert not out.exists() and not (tmp_path / "o.links.csv").exists()


def test_keypoints_on_the_border_are_read(tmp_path, capsys):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)

    def to_the_corners(kp):
        kp[0, :2] = (0.0, 0.0)
        kp[1, :2] = (320.0, 240.0)

    _set_keypoints(db, "view_1.jpg", to_the_corners)
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--no-rerun"]) == 0
