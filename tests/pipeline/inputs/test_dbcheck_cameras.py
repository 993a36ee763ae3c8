"""A database whose image names a camera the cameras table lacks is refused in one line.

COLMAP's mapper stops on such an image (``clean-db --fusion`` ended in a traceback from
pycolmap, ``Camera 2 from rig 2 not found``); without ``--fusion`` the loop check silently
judged none of that image's pairs.
"""

import hashlib
import sqlite3
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import one_line_error  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


@pytest.mark.parametrize("extra", [[], ["--fusion"], ["--loop-check"]])
def test_an_image_without_its_camera_is_refused(tmp_path, capsys, extra):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    con = sqlite3.connect(db)
    camera_id = con.execute("SELECT camera_id FROM images WHERE name = 'view_2.jpg'").fetchone()[0]
    con.execute("UPDATE images SET camera_id = 77 WHERE name = 'view_2.jpg'")
    con.commit()
    con.close()
    digest = hashlib.sha256(db.read_bytes()).hexdigest()
    out = tmp_path / "o.db"
    assert main(["clean-db", str(db), "--out", str(out), "--no-rerun", *extra]) == 2
    one_line_error(capsys, "table images, image_id", "'view_2.jpg'",
                   "names camera_id 77, which is not in the cameras table")
    assert camera_id != 77
    assert hashlib.sha256(db.read_bytes()).hexdigest() == digest
    assert not out.exists() and not (tmp_path / "o.links.csv").exists()
