"""clean-db --ignore-watermarks: a WATERMARK pair takes no part and is copied unchanged."""

import json
import sqlite3

import pycolmap
import pytest

from pipeline import colmap
from pipeline.__main__ import main
from tests.pipeline.commands.test_clean_db import _db_with_planted_conflicts

WATERMARK = int(pycolmap.TwoViewGeometryConfiguration.WATERMARK)


def _row(path, pair_id):
    con = sqlite3.connect(path)
    try:
        return con.execute("SELECT * FROM two_view_geometries WHERE pair_id = ?",
                           (pair_id,)).fetchone()
    finally:
        con.close()


@pytest.fixture
def watermark_db(tmp_path):
    """The planted-conflict database with its pair view_0 / view_2 marked WATERMARK: that pair
    holds one link, (0, 1)-(2, 0), the chord that closes one planted conflictive set."""
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    pid = int(pycolmap.image_pair_to_pair_id(1, 3))  # image ids are camera index + 1
    con = sqlite3.connect(src)
    with con:
        con.execute("UPDATE two_view_geometries SET config = ? WHERE pair_id = ?",
                    (WATERMARK, pid))
    con.close()
    return src, pid


def _links(contents):
    return set(zip(contents.links.cam_i.tolist(), contents.links.feat_i.tolist(),
                   contents.links.cam_j.tolist(), contents.links.feat_j.tolist(), strict=True))


def test_watermark_pair_gives_no_link_and_is_copied_unchanged(tmp_path, watermark_db, capsys):
    src, pid = watermark_db
    out, report = tmp_path / "out.db", tmp_path / "r.json"
    assert main(["clean-db", str(src), "--out", str(out), "--report", str(report),
                 "--no-rerun", "--ignore-watermarks"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads(report.read_text())
    assert summary["ignored_watermark_pairs"] == 1
    assert "WATERMARK image pairs ignored (--ignore-watermarks): 1" in printed
    # without the chord only the other planted cycle is a conflict
    assert summary["before"]["conflictive_sets"] == 1
    assert summary["links"] == len(colmap.read_database(src).links) - 1
    assert _row(out, pid) == _row(src, pid)  # the WATERMARK row, byte for byte
    cleaned = colmap.read_database(out)  # read as the default mapper: the chord is still there
    assert (0, 1, 2, 0) in _links(cleaned)
    assert colmap.read_database(out, ignore_watermarks=True).watermark_pairs_ignored == 1


def test_without_the_flag_the_watermark_pair_is_an_ordinary_pair(tmp_path, watermark_db, capsys):
    src, pid = watermark_db
    out, report = tmp_path / "out.db", tmp_path / "r.json"
    assert main(["clean-db", str(src), "--out", str(out), "--report", str(report),
                 "--no-rerun"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads(report.read_text())
    assert "ignored_watermark_pairs" not in summary and "WATERMARK" not in printed
    assert summary["before"]["conflictive_sets"] == 2
    assert summary["links"] == len(colmap.read_database(src).links)
    assert colmap.read_database(src).watermark_pairs_ignored == 0


def test_a_database_of_watermark_pairs_only_is_copied_unchanged_with_a_warning(tmp_path, capsys):
    """Every pair a WATERMARK pair leaves no link: an empty input, as a database whose pairs
    hold no inliers is, warned of and copied unchanged (it stopped with exit 2)."""
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    con = sqlite3.connect(src)
    with con:
        con.execute("UPDATE two_view_geometries SET config = ?", (WATERMARK,))
    con.close()
    pairs = colmap.read_database(src, ignore_watermarks=True).watermark_pairs_ignored
    out = tmp_path / "o.db"
    assert main(["clean-db", str(src), "--out", str(out), "--no-rerun",
                 "--ignore-watermarks"]) == 0
    err = capsys.readouterr().err
    assert ("warning: the input holds no link between two images: there is nothing to "
            f"associate (its {pairs} verified image pair(s) are all WATERMARK pairs, which "
            "--ignore-watermarks leaves out and copies unchanged; drop --ignore-watermarks to "
            "clean them)") in err, err
    assert (tmp_path / "o.links.csv").read_text().splitlines() == [
        "cam_i,feat_i,cam_j,feat_j,status,reason,round,truth"]
    query = "SELECT * FROM two_view_geometries ORDER BY pair_id"
    with sqlite3.connect(src) as a, sqlite3.connect(out) as b:
        assert a.execute(query).fetchall() == b.execute(query).fetchall() != []
