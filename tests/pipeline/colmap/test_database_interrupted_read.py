"""pipeline.colmap.read_database: a Ctrl-C (or a SIGTERM, or any error) while the database's
snapshot is being taken removes the snapshot. One arriving during SQLite's ``VACUUM INTO``
left ``colmap-read-*/read.db``, a full copy of the database, in the temporary folder at every
interrupted clean-db."""

import sqlite3
import tempfile

import numpy as np
import pytest

import pipeline.colmap.database as database
from pipeline.types import Features, Links, View


def _small_database(path):
    rng = np.random.default_rng(0)
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    views = [View(f"view_{k}.jpg", np.zeros((240, 320, 3), np.uint8), K) for k in range(3)]
    feats = [Features(rng.uniform([0, 0], [319, 239], size=(20, 2)).astype(np.float32),
                      np.zeros((20, 128), np.float32), np.ones(20, np.float32), "sift")
             for _ in views]
    rows = np.array([(0, r, 1, r) for r in range(12)] + [(1, r, 2, r) for r in range(12)])
    database.write_database(path, views, feats, Links(*rows.T))


class _InterruptedSnapshot:
    """The user's database opened read only, with a Ctrl-C arriving once SQLite has written
    the snapshot (``VACUUM INTO``) and before the call returns."""

    def __init__(self, con: sqlite3.Connection) -> None:
        self._con = con

    def execute(self, sql, *args):
        out = self._con.execute(sql, *args)
        if sql.startswith("VACUUM INTO"):
            raise KeyboardInterrupt
        return out

    def __getattr__(self, name):
        return getattr(self._con, name)


@pytest.mark.parametrize("when", ["vacuum", "contents"])
def test_an_interrupt_while_the_snapshot_is_taken_leaves_no_copy(tmp_path, monkeypatch, when):
    src = tmp_path / "in.db"
    _small_database(src)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    if when == "vacuum":
        opened = database.open_readonly
        monkeypatch.setattr(database, "open_readonly",
                            lambda path: _InterruptedSnapshot(opened(path)))
    else:
        def interrupted(*args, **kwargs):
            raise KeyboardInterrupt

        monkeypatch.setattr(database, "_contents", interrupted)
    with pytest.raises(KeyboardInterrupt):
        database.read_database(src)
    assert sorted(p.name for p in tmp.iterdir()) == []


def test_a_read_keeps_its_snapshot_until_closed(tmp_path, monkeypatch):
    src = tmp_path / "in.db"
    _small_database(src)
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    contents = database.read_database(src)
    assert contents.snapshot.is_file() and contents.snapshot.parent.parent == tmp
    contents.close()
    assert sorted(p.name for p in tmp.iterdir()) == []
