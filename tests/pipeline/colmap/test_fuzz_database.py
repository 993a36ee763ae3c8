"""Fuzzed COLMAP databases of ``clean-db``: a value of another type or out of range in any
column of any table, rows removed or repeated, a table dropped, damaged bytes: the reader
returns valid links or an InputError naming the database."""

import functools
import sqlite3
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline import colmap
from pipeline.__main__ import main
from pipeline.types import Features, Links, View

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, read_or_refuse  # noqa: E402

N, M = 3, 12


@functools.lru_cache(maxsize=1)
def _valid() -> bytes:
    """A small database: three images of 12 keypoints, a ring of verified pairs."""
    rng = np.random.default_rng(0)
    views, feats = [], []
    for k in range(N):
        K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
        views.append(View(f"view_{k}.jpg", np.zeros((240, 320, 3), np.uint8), K))
        kp = rng.uniform([0, 0], [319, 239], size=(M, 2)).astype(np.float32)
        feats.append(Features(kp, np.zeros((M, 128), np.float32), np.ones(M, np.float32), "sift"))
    rows = [(a, r, b, r) for r in range(8) for a, b in ((0, 1), (1, 2), (0, 2))]
    ci, fi, cj, fj = np.array(rows).T
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "in.db"
        colmap.write_database(path, views, feats, Links(ci, fi, cj, fj))
        return path.read_bytes()


def _schema() -> dict[str, list[str]]:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "in.db"
        path.write_bytes(_valid())
        con = sqlite3.connect(path)
        tables = [r[0] for r in con.execute(
            "SELECT name FROM sqlite_master WHERE type='table' AND name NOT LIKE 'sqlite_%'")]
        out = {t: [r[1] for r in con.execute(f"PRAGMA table_info({t})")] for t in tables}
        con.close()
        return out


SCHEMA = _schema()
VALUES = st.one_of(st.sampled_from([None, -1, 0, 1, 2, 3, 2**31 - 1, 2**31, 2**63 - 1,
                                    -2**63, 1.5, float("nan"), float("inf"), "", "x",
                                    "view_1.jpg", "\u00e9", b"", b"\x00" * 4, b"\xff" * 8]),
                   st.binary(max_size=40), st.integers(-10, 10))


@st.composite
def damages(draw):
    ops = []
    for _ in range(draw(st.integers(1, 3))):
        table = draw(st.sampled_from(sorted(SCHEMA)))
        op = draw(st.sampled_from(["set", "set", "set", "delete", "repeat", "drop"]))
        if op == "set":
            ops.append((op, table, draw(st.sampled_from(SCHEMA[table])), draw(VALUES),
                        draw(st.integers(0, 5))))
        else:
            ops.append((op, table, None, None, draw(st.integers(0, 5))))
    return ops


def _apply(path: Path, ops) -> None:
    con = sqlite3.connect(path)
    for op, table, col, value, k in ops:
        try:
            rowids = [r[0] for r in con.execute(f"SELECT rowid FROM {table}")]
        except sqlite3.Error:
            continue  # dropped by an earlier damage
        if op == "drop":
            con.execute(f"DROP TABLE {table}")
        elif not rowids:
            continue
        elif op == "set":
            try:
                con.execute(f"UPDATE {table} SET {col} = ? WHERE rowid = ?",
                            (value, rowids[k % len(rowids)]))
            except sqlite3.Error:
                pass  # a constraint of the schema (NOT NULL, UNIQUE) keeps the value out
        elif op == "delete":
            con.execute(f"DELETE FROM {table} WHERE rowid = ?", (rowids[k % len(rowids)],))
        else:
            try:
                con.execute(f"INSERT INTO {table} SELECT * FROM {table} WHERE rowid = ?",
                            (rowids[k % len(rowids)],))
            except sqlite3.Error:
                pass
    con.commit()
    con.close()


def _check(contents) -> None:
    lk = contents.links
    m = np.array([len(k) for k in contents.keypoints])
    assert (lk.cam_i < lk.cam_j).all() and (lk.cam_j < len(m)).all()
    assert ((lk.feat_i >= 0) & (lk.feat_i < m[lk.cam_i])).all()
    assert ((lk.feat_j >= 0) & (lk.feat_j < m[lk.cam_j])).all()
    for kp in contents.keypoints:
        assert np.isfinite(kp).all()


@FUZZ
@given(damages())
def test_a_database_with_wrong_values_is_read_or_refused(ops):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "in.db"
        path.write_bytes(_valid())
        _apply(path, ops)
        contents = read_or_refuse(lambda: colmap.read_database(path), str(path))
        if contents is not None:
            _check(contents)


@FUZZ
@given(st.data())
def test_a_damaged_database_file_is_read_or_refused(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "in.db"
        path.write_bytes(data.draw(bytes_mutant(_valid(), max_ops=4)))
        contents = read_or_refuse(lambda: colmap.read_database(path), str(path))
        if contents is not None:
            _check(contents)


@pytest.mark.parametrize("value", [-1, b"", b"\x00" * 8, bytes(range(16))])
def test_a_two_view_geometry_camera_blob_asking_for_memory_is_refused(tmp_path, capsys, value):
    # COLMAP's reader sized a buffer from it: std::bad_alloc, which the command line called
    # running out of memory ("try a smaller input") on a database of a few kilobytes
    path = tmp_path / "in.db"
    path.write_bytes(_valid())
    con = sqlite3.connect(path)
    con.execute("UPDATE two_view_geometries SET camera1 = ? WHERE rowid = "
                "(SELECT min(rowid) FROM two_view_geometries)", (value,))
    con.commit()
    con.close()
    assert main(["clean-db", str(path), "--out", str(tmp_path / "out.db")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "try a smaller input" not in err
    assert err.strip().splitlines()[-1].startswith(
        f"error: {str(path)!r} could not be read as a COLMAP database (out of memory")
    assert "the database is corrupt" in err and not (tmp_path / "out.db").exists()
