"""pipeline.colmap.database: a two-view geometry naming a keypoint an image does not have is
refused with that image, that keypoint and the image's count."""

import sqlite3

import numpy as np

from pipeline import colmap
from pipeline.__main__ import main
from pipeline.types import Features, Links, View

MAX_PAIR = 2147483647


def _db(path):
    """Two images, 10 and 40 keypoints; keypoint r of each matched for r < 8."""
    rng = np.random.default_rng(0)
    views, feats = [], []
    for k, m in enumerate((10, 40)):
        K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
        views.append(View(f"v{k}.jpg", np.zeros((240, 320, 3), np.uint8), K))
        kp = rng.uniform([0, 0], [319, 239], size=(m, 2)).astype(np.float32)
        feats.append(Features(kp, np.zeros((m, 128), np.float32), np.ones(m, np.float32), "sift"))
    r = np.arange(8)
    colmap.write_database(path, views, feats, Links(np.zeros(8, int), r, np.ones(8, int), r))


def _spoil_first_inlier(path, first, second):
    with sqlite3.connect(path) as c:
        pid, rows, cols, data = c.execute(
            "select pair_id, rows, cols, data from two_view_geometries").fetchone()
        assert divmod(pid, MAX_PAIR) == (1, 2)  # image ids 1 (v0.jpg), 2 (v1.jpg)
        m = np.frombuffer(data, np.uint32).reshape(rows, cols).copy()
        m[0] = (first, second)
        c.execute("update two_view_geometries set data = ? where pair_id = ?",
                  (m.tobytes(), pid))


def _error(tmp_path, capsys):
    out = tmp_path / "out.db"
    code = main(["clean-db", str(tmp_path / "in.db"), "--out", str(out), "--no-rerun"])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists() and "Traceback" not in err
    return err.strip().splitlines()[-1]


def test_the_image_whose_keypoint_is_missing_is_named_not_the_larger_index(tmp_path, capsys):
    # keypoint 12 of v0.jpg (10 keypoints) is missing; 30 of v1.jpg (40) exists
    _db(tmp_path / "in.db")
    _spoil_first_inlier(tmp_path / "in.db", 12, 30)
    assert _error(tmp_path, capsys) == (
        f"error: database {str(tmp_path / 'in.db')!r}: a two-view geometry of v0.jpg / v1.jpg "
        "names keypoint 12 of v0.jpg, which has 10 stored keypoints; the database is "
        "inconsistent (rebuild it with COLMAP)")


def test_the_second_image_is_named_when_its_keypoint_is_missing(tmp_path, capsys):
    _db(tmp_path / "in.db")
    _spoil_first_inlier(tmp_path / "in.db", 3, 41)
    assert "names keypoint 41 of v1.jpg, which has 40 stored keypoints" in \
        _error(tmp_path, capsys)
