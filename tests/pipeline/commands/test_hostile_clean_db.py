"""clean-db, as a hostile user would run it: one line on stderr, exit 2, input untouched."""

import hashlib
import shutil
import sqlite3
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error, refused  # noqa: E402
from test_clean_db import _db_with_planted_conflicts  # noqa: E402


@pytest.fixture(scope="module")
def source_db(tmp_path_factory):
    path = tmp_path_factory.mktemp("db") / "in.db"
    _db_with_planted_conflicts(path)
    return path


@pytest.fixture
def db(source_db, tmp_path):
    path = tmp_path / "in.db"
    shutil.copy(source_db, path)
    return path


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()




def test_report_onto_the_database_is_refused(db, tmp_path, capsys):
    digest = _sha(db)
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--report", str(db),
                 "--overwrite"]) == 2
    one_line_error(capsys, "--report", "input file given as IN.db")
    assert _sha(db) == digest and not (tmp_path / "o.db").exists()


def test_out_naming_a_folder_is_refused(db, tmp_path, capsys):
    (tmp_path / "folder").mkdir()
    assert main(["clean-db", str(db), "--out", str(tmp_path / "folder")]) == 2
    one_line_error(capsys, "is a folder")
    assert list((tmp_path / "folder").iterdir()) == []


def test_existing_output_is_refused_unless_overwrite(db, tmp_path, capsys):
    out = tmp_path / "o.db"
    out.write_bytes(b"precious")
    assert main(["clean-db", str(db), "--out", str(out)]) == 2
    one_line_error(capsys, "already exists; pass --overwrite")
    assert out.read_bytes() == b"precious"
    assert main(["clean-db", str(db), "--out", str(out), "--overwrite"]) == 0


def test_out_through_a_hard_link_to_the_input_is_refused(db, tmp_path, capsys):
    import os

    os.link(db, tmp_path / "alias.db")
    assert main(["clean-db", str(db), "--out", str(tmp_path / "alias.db"), "--overwrite"]) == 2
    one_line_error(capsys, "input file")


def test_read_only_location_is_aone_line_error(db, tmp_path, capsys, monkeypatch):
    from pipeline import outputs

    monkeypatch.setattr(outputs.os, "access", lambda p, mode: False)
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db")]) == 2
    one_line_error(capsys, "cannot write in")


@pytest.mark.parametrize("sql,message", [
    ("UPDATE two_view_geometries SET pair_id = 2147483647 * 998 + 999 "
     "WHERE pair_id = (SELECT min(pair_id) FROM two_view_geometries)",
     "names image_id 998, which is not in the images table"),
    ("UPDATE two_view_geometries SET rows = -5 "
     "WHERE pair_id = (SELECT min(pair_id) FROM two_view_geometries)",
     "rows=-5"),
    ("UPDATE keypoints SET rows = -5 WHERE image_id = 1", "table keypoints, image_id 1: rows=-5"),
    ("UPDATE keypoints SET rows = 100000000 WHERE image_id = 1", "bytes of data"),
    ("UPDATE matches SET cols = 7", "table matches"),
])
def test_corrupt_tables_are_one_line_errors(db, tmp_path, capsys, sql, message):
    con = sqlite3.connect(db)
    con.execute(sql)
    con.commit()
    con.close()
    digest = _sha(db)
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db")]) == 2
    one_line_error(capsys, message, str(db))
    assert _sha(db) == digest and not (tmp_path / "o.db").exists()


def test_comm_graph_naming_a_folder_says_so(db, tmp_path, capsys):
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db"),
                 "--comm-graph", str(tmp_path)]) == 2
    one_line_error(capsys, "is a folder")


def test_ctrl_c_is_one_line_exit_130_and_nothing_written(db, tmp_path, capsys, monkeypatch):
    import pipeline.consistency as consistency

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(consistency, "resolve_conflicts", interrupted)
    assert main(["clean-db", str(db), "--out", str(tmp_path / "o.db")]) == 130
    assert capsys.readouterr().err.startswith("interrupted:")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.db"]


@pytest.mark.parametrize("case", ["missing", "lacks-an-image"])
def test_an_image_dir_that_cannot_serve_is_refused_before_anything_is_written(db, tmp_path,
                                                                             capsys, case):
    images = tmp_path / "images"
    if case == "lacks-an-image":
        images.mkdir()
        (images / "view_0.jpg").write_bytes(b"")
    refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db"), "--image-dir",
                     str(images)], tmp_path, "--image-dir",
            "is not a folder" if case == "missing" else "no image 'view_1.jpg'")
    assert sorted(p.name for p in tmp_path.iterdir()) == (
        ["in.db"] if case == "missing" else ["images", "in.db"])


def test_outputs_follow_the_umask(db, tmp_path, capsys):
    import os

    out = tmp_path / "o.db"
    mask = os.umask(0o022)
    try:
        assert main(["clean-db", str(db), "--out", str(out), "--report",
                     str(tmp_path / "r.json")]) == 0
    finally:
        os.umask(mask)
    for name in ("o.db", "o.links.csv", "o.rrd", "r.json"):
        assert oct((tmp_path / name).stat().st_mode & 0o777) == oct(0o644), name
