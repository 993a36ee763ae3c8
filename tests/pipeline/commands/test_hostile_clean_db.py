"""clean-db, as a hostile user would run it: one line on stderr, exit 2, input untouched."""

import hashlib
import shutil
import sqlite3
import sys
from pathlib import Path

import numpy as np
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


def test_read_only_location_is_aone_line_error(db, tmp_path, capsys, refuse_writes_in):
    refuse_writes_in(tmp_path)
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


# ------------------------------------------------------------- wrong results as success

M = 2147483647


def _geometries(path):
    con = sqlite3.connect(path)
    try:
        return {pid: np.frombuffer(data or b"", np.uint32).reshape(-1, 2).copy()
                for pid, data in con.execute("SELECT pair_id, data FROM two_view_geometries")}
    finally:
        con.close()


def _conflictive_sets_of(out):
    from pipeline import colmap
    from pipeline.association import AssociationGraph, count_conflicts

    got = colmap.read_database(out)
    return count_conflicts(AssociationGraph(got.features_per_camera, got.links)).conflictive_sets


def test_a_pair_stored_the_other_way_round_is_cleaned_in_the_database(db, tmp_path, capsys):
    """A row stored as (image 2, image 1): its cut links must leave OUT.db too."""
    con = sqlite3.connect(db)
    for pid, data in con.execute("SELECT pair_id, data FROM two_view_geometries "
                                 "ORDER BY pair_id").fetchall():
        a, b = divmod(pid, M)
        m = np.frombuffer(data, np.uint32).reshape(-1, 2)[:, ::-1].copy()
        con.execute("UPDATE two_view_geometries SET pair_id = ?, data = ? WHERE pair_id = ?",
                    (b * M + a, m.tobytes(), pid))
    con.commit()
    con.close()
    out = tmp_path / "o.db"
    assert main(["clean-db", str(db), "--out", str(out), "--no-rerun"]) == 0
    assert "conflictive sets: 2 before, 0 after" in capsys.readouterr().out
    assert _conflictive_sets_of(out) == 0
    # each row kept its stored orientation, with only the kept links
    stored, cleaned = _geometries(db), _geometries(out)
    assert set(stored) == set(cleaned)
    assert sum(len(v) for v in cleaned.values()) < sum(len(v) for v in stored.values())
    for pid, m in cleaned.items():
        assert {tuple(r) for r in m.tolist()} <= {tuple(r) for r in stored[pid].tolist()}


def _retype_pair_ids(db, expression):
    """Rebuild two_view_geometries with an untyped pair_id set to ``expression``."""
    con = sqlite3.connect(db)
    con.executescript(f"""
        CREATE TABLE tvg AS SELECT * FROM two_view_geometries;
        DROP TABLE two_view_geometries;
        CREATE TABLE two_view_geometries (pair_id, rows INTEGER NOT NULL,
            cols INTEGER NOT NULL, data BLOB, config INTEGER NOT NULL, F BLOB, E BLOB,
            H BLOB, qvec BLOB, tvec BLOB, camera1 BLOB, camera2 BLOB);
        INSERT INTO two_view_geometries SELECT {expression}, rows, cols, data, config, F, E,
            H, qvec, tvec, camera1, camera2 FROM tvg;
        DROP TABLE tvg;
    """)
    con.commit()
    con.close()


@pytest.mark.parametrize("expression,kind", [
    ("CAST(pair_id AS REAL)", "real"),
    ("CAST(pair_id AS TEXT)", "text"),
    ("CAST(CAST(pair_id AS TEXT) AS BLOB)", "blob"),
    ("NULL", "null"),
])
def test_a_pair_id_that_is_not_an_integer_is_refused(db, tmp_path, capsys, expression, kind):
    _retype_pair_ids(db, expression)
    refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db")], tmp_path,
            "pair_id", f"is stored as {kind}, not an integer")


def test_a_pair_stored_twice_is_refused(db, tmp_path, capsys):
    _retype_pair_ids(db, "pair_id")
    con = sqlite3.connect(db)
    con.execute("INSERT INTO two_view_geometries SELECT * FROM two_view_geometries LIMIT 1")
    con.commit()
    con.close()
    refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db")], tmp_path,
            "is stored in 2 rows")


def test_changes_still_in_the_write_ahead_log_are_read(db, tmp_path, capsys):
    """Another program holds the database open with changes not yet checkpointed into the
    main file: they are part of the database, and are read."""
    writer = sqlite3.connect(db)
    writer.execute("PRAGMA wal_autocheckpoint = 0")
    pid = writer.execute("SELECT max(pair_id) FROM two_view_geometries").fetchone()[0]
    writer.execute("UPDATE two_view_geometries SET rows = 0, data = x'' WHERE pair_id = ?",
                   (pid,))
    writer.commit()
    try:
        assert (db.parent / "in.db-wal").stat().st_size > 0
        out = tmp_path / "o.db"
        assert main(["clean-db", str(db), "--out", str(out), "--no-rerun"]) == 0
        assert len(_geometries(out)[pid]) == 0
        assert _conflictive_sets_of(out) == 0
    finally:
        writer.close()


def test_an_output_whose_write_ahead_log_lies_beside_it_is_refused(db, tmp_path, capsys):
    """OUT.db open in another program (a COLMAP session) with changes in OUT.db-wal: a new
    OUT.db put there took that log for its own, here every two-view geometry deleted."""
    out = tmp_path / "o.db"
    assert main(["clean-db", str(db), "--out", str(out), "--no-rerun"]) == 0
    writer = sqlite3.connect(out)
    writer.execute("PRAGMA wal_autocheckpoint = 0")
    writer.execute("DELETE FROM two_view_geometries")
    writer.commit()
    try:
        before = {p.name: _sha(p) for p in tmp_path.iterdir() if p.is_file()}
        assert main(["clean-db", str(db), "--out", str(out), "--no-rerun", "--overwrite"]) == 2
        one_line_error(capsys, "o.db-wal' beside it holds changes")
        assert {p.name: _sha(p) for p in tmp_path.iterdir() if p.is_file()} == before
    finally:
        writer.close()


# ---------------------------------------------------------------- not a database at all

@pytest.mark.parametrize("case,message", [
    ("fifo", "not a regular file"), ("folder", "is a folder"), ("/dev/zero", "not a regular"),
])
def test_a_special_file_as_the_database_is_named_as_such(tmp_path, capsys, case, message):
    import os

    target = {"fifo": tmp_path / "in.db", "folder": tmp_path / "in.db"}.get(case, Path(case))
    if case == "fifo":
        os.mkfifo(target)
    elif case == "folder":
        target.mkdir()
    refused(capsys, ["clean-db", str(target), "--out", str(tmp_path / "o.db")], tmp_path,
            message)


def test_a_database_is_checked_before_anything_is_copied(tmp_path, capsys, monkeypatch):
    """A large file that only starts like a database is refused without being copied."""
    import shutil as sh

    big = tmp_path / "in.db"
    with open(big, "wb") as f:
        f.write(b"SQLite format 3\x00" + b"\x10\x00" + b"\x01" * 82)
        f.truncate(2**31)  # sparse: 2 GB declared, nothing stored
    copied = []
    monkeypatch.setattr(sh, "copyfile", lambda *a, **k: copied.append(a))
    assert main(["clean-db", str(big), "--out", str(tmp_path / "o.db")]) == 2
    one_line_error(capsys, str(big))
    assert copied == [] and sorted(p.name for p in tmp_path.iterdir()) == ["in.db"]


def test_the_memory_guard_counts_what_the_tables_declare(db, tmp_path, capsys):
    """Keypoints and matches are counted from their declared sizes before anything is read."""
    refused(capsys, ["clean-db", str(db), "--out", str(tmp_path / "o.db"),
                     "--max-memory-gb", "0.00001"], tmp_path,
            "keypoints and verified matches of the database", "--max-memory-gb")
