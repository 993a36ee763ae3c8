"""A rig naming a camera the cameras table lacks is refused in one line: ``clean-db --fusion``
ended in a traceback from COLMAP's mapper (``Camera 2 from rig 1 not found in the
reconstruction``), and COLMAP's own mapper stops on the cleaned copy alike."""

import sqlite3
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import refused  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


@pytest.mark.parametrize("sql, table", [
    ("INSERT INTO rig_sensors (rig_id, sensor_id, sensor_type) VALUES ({rig}, 55, 0)",
     "rig_sensors"),
    ("UPDATE rigs SET ref_sensor_id = 55 WHERE rig_id = {rig}", "rigs"),
], ids=["rig-sensor", "reference-sensor"])
def test_a_rig_of_a_missing_camera_is_refused(tmp_path, capsys, sql, table):
    db = tmp_path / "in.db"
    _db_with_planted_conflicts(db)
    con = sqlite3.connect(db)
    rig = con.execute("SELECT min(rig_id) FROM rigs").fetchone()[0]
    assert con.execute("SELECT count(*) FROM cameras WHERE camera_id = 55").fetchone()[0] == 0
    con.execute(sql.format(rig=rig))
    con.commit()
    con.close()
    line = refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--no-rerun",
                            "--fusion"], tmp_path)
    assert line == (f"error: database {str(db)!r}, table {table}, rig_id {rig}: names camera "
                    "55, which is not in the cameras table; the database is inconsistent "
                    "(rebuild it with COLMAP)")
