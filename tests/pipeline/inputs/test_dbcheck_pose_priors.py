"""A pose prior whose matrix is stored with another size than its values need is refused in
one line: ``clean-db --fusion`` ended in a traceback from COLMAP's mapper (``Check failed:
num_bytes == matrix.size() * sizeof(...) (3 vs. 24)``), and COLMAP's own mapper stops on the
cleaned copy alike. NULL matrices (none stored) are read."""

import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import refused  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


def _db(tmp_path, position, covariance):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    con = sqlite3.connect(db)
    image_id, camera_id = con.execute("SELECT image_id, camera_id FROM images").fetchone()
    con.execute("INSERT INTO pose_priors (pose_prior_id, corr_data_id, corr_sensor_id, "
                "corr_sensor_type, position, position_covariance, coordinate_system) "
                "VALUES (7, ?, ?, 0, ?, ?, 0)", (image_id, camera_id, position, covariance))
    con.commit()
    con.close()
    return db


@pytest.mark.parametrize("position, covariance, needle", [
    (b"\0\0\0", None, "position holds 3 bytes, expected 24 (3 float64 values) or NULL"),
    (np.zeros(3).tobytes(), np.zeros(1).tobytes(),
     "position_covariance holds 8 bytes, expected 72 (9 float64 values) or NULL"),
], ids=["position", "covariance"])
def test_a_pose_prior_of_the_wrong_size_is_refused(tmp_path, capsys, position, covariance,
                                                    needle):
    db = _db(tmp_path, position, covariance)
    line = refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--no-rerun",
                            "--fusion"], tmp_path)
    assert line == (f"error: database {str(db)!r}, table pose_priors, pose_prior_id 7: {needle}; "
                    "the database is corrupt (rebuild it with COLMAP, or delete that row)")


@pytest.mark.parametrize("position, covariance", [
    (None, None), (np.zeros(3).tobytes(), np.eye(3).tobytes())], ids=["null", "whole"])
def test_pose_priors_of_their_sizes_are_read(tmp_path, capsys, position, covariance):
    db = _db(tmp_path, position, covariance)
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--no-rerun"]) == 0
    assert "conflictive sets: 2 before, 0 after" in capsys.readouterr().out
