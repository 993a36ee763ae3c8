"""A database without a cameras table is refused in one line, as one whose images name
cameras the table lacks: ``clean-db --fusion`` ended in a traceback from COLMAP's mapper
(``Camera 1 from rig 1 not found``) and ``--loop-check`` judged none of the pairs."""

import hashlib
import sqlite3
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


@pytest.mark.parametrize("extra", [[], ["--fusion"], ["--loop-check"]])
def test_a_database_without_its_cameras_table_is_refused(tmp_path, capsys, extra):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    with sqlite3.connect(db) as con:
        first = con.execute("SELECT image_id, name, camera_id FROM images ORDER BY image_id"
                            ).fetchone()
        con.execute("DROP TABLE cameras")
    digest = hashlib.sha256(db.read_bytes()).hexdigest()
    out = tmp_path / "o.db"
    assert main(["clean-db", str(db), "--out", str(out), "--no-rerun", *extra]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert [x for x in err.splitlines() if x.startswith("error:")] == [
        f"error: database {str(db)!r}, table images, image_id {first[0]} ({first[1]!r}): names "
        f"camera_id {first[2]}, but the database has no cameras table; the database is "
        "inconsistent (rebuild it with COLMAP)"]
    assert hashlib.sha256(db.read_bytes()).hexdigest() == digest
    assert not out.exists() and not (tmp_path / "o.links.csv").exists()
