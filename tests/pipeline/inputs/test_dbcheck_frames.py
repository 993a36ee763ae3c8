"""A database whose rig and frame tables leave an image without its frame is refused in one
line: ``clean-db --fusion`` ended in a traceback from COLMAP's mapper (``Check failed:
image.HasFrameId()``, ``Frame with ID 77 does not exist``, ``rig.HasSensor``), and COLMAP's
own mapper stops on the cleaned copy alike. A database without frames is read as before."""

import sqlite3
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import refused  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


def _db(tmp_path, *sql):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    con = sqlite3.connect(db)
    image_id, camera_id = con.execute(
        "SELECT image_id, camera_id FROM images WHERE name = 'view_2.jpg'").fetchone()
    for statement in sql:
        con.execute(statement.format(image=image_id, camera=camera_id))
    con.commit()
    con.close()
    return db, image_id


@pytest.mark.parametrize("sql, needle", [
    (["DELETE FROM frame_data WHERE data_id = {image}"],
     "in no frame (table frame_data has no camera row with data_id {image}), though the frames "
     "table holds 4 frame(s)"),
    (["DROP TABLE frame_data"], "in no frame (table frame_data has no camera row"),
    (["UPDATE frame_data SET frame_id = 77 WHERE data_id = {image}"],
     "table frame_data puts it in frame_id 77, which is not in the frames table"),
    (["UPDATE frame_data SET sensor_id = 55 WHERE data_id = {image}"],
     "table frame_data gives it camera 55 of frame"),
], ids=["no-frame-data-row", "no-frame-data-table", "frame-missing", "camera-not-in-rig"])
def test_an_image_without_its_frame_is_refused(tmp_path, capsys, sql, needle):
    db, image_id = _db(tmp_path, *sql)
    line = refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--no-rerun",
                            "--fusion"], tmp_path, needle.format(image=image_id))
    assert line.startswith(f"error: database {str(db)!r}, table images, image_id ")
    if "DROP" not in sql[0]:  # without the table, the first image is named
        assert f"image_id {image_id} ('view_2.jpg')" in line
    assert line.endswith("the database is inconsistent (rebuild it with COLMAP)")


@pytest.mark.parametrize("sql", [
    ["DELETE FROM frame_data", "DELETE FROM frames"],
    ["DROP TABLE frame_data", "DROP TABLE frames"],
    ["DELETE FROM rigs"],
], ids=["frames-emptied", "frames-dropped", "rigs-emptied"])
def test_a_database_without_frames_is_read(tmp_path, capsys, sql):
    db, _ = _db(tmp_path, *sql)
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--no-rerun"]) == 0
    assert "conflictive sets: 2 before, 0 after" in capsys.readouterr().out
