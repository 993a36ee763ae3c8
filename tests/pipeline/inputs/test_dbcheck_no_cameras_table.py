"""A database without a cameras table is refused in one line, as one whose images name
cameras the table lacks: ``clean-db --fusion`` ended in a traceback from COLMAP's mapper
(``Camera 1 from rig 1 not found``) and ``--loop-check`` judged none of the pairs."""

import sqlite3
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import refused  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


@pytest.mark.parametrize("extra", [[], ["--fusion"], ["--loop-check"]])
def test_a_database_without_its_cameras_table_is_refused(tmp_path, capsys, extra):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    with sqlite3.connect(db) as con:
        first = con.execute("SELECT image_id, name, camera_id FROM images ORDER BY image_id"
                            ).fetchone()
        con.execute("DROP TABLE cameras")
    con.close()  # (the with block only commits)
    line = refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--no-rerun",
                            *extra], tmp_path)
    assert line == (f"error: database {str(db)!r}, table images, image_id {first[0]} "
                    f"({first[1]!r}): names camera_id {first[2]}, but the database has no "
                    "cameras table; the database is inconsistent (rebuild it with COLMAP)")
