"""An image name stored in a COLMAP database as bytes that are not UTF-8 (a BLOB) is refused
in one line naming the image: ``clean-db`` ended in a UnicodeDecodeError traceback from
pycolmap's reading of the images."""

import sqlite3
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import refused  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


def _db(tmp_path, name):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    con = sqlite3.connect(db)
    image_id = con.execute("SELECT image_id FROM images WHERE name = 'view_2.jpg'").fetchone()[0]
    con.execute("UPDATE images SET name = ? WHERE image_id = ?", (name, image_id))
    con.commit()
    con.close()
    return db, image_id


@pytest.mark.parametrize("name", [b"\x80", b"view_\xff.jpg"])
def test_a_name_that_is_not_utf8_is_refused(tmp_path, capsys, name):
    db, image_id = _db(tmp_path, name)
    refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "out.db")], tmp_path,
            f"database {str(db)!r}, table images, image_id {image_id}: name {name!r} is not "
            "UTF-8 text; the database is corrupt (rebuild it with COLMAP)")


def test_a_name_stored_as_utf8_bytes_is_read(tmp_path, capsys):
    db, _ = _db(tmp_path, b"view_2.jpg")
    assert main(["clean-db", str(db), "--out", str(tmp_path / "out.db")]) == 0, \
        capsys.readouterr().err
