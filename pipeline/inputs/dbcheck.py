"""Sanity checks of a COLMAP database's tables before pycolmap reads them.

pycolmap trusts the ``rows``/``cols`` columns of its tables: a negative ``rows`` makes it
allocate without bound (``std::bad_alloc``) and a pair id naming an image that does not
exist surfaces later as a KeyError. A database is a file a user (or an attacker) hands us, so
it is read here first with :mod:`sqlite3` (read only) and every problem becomes one
:class:`~pipeline.errors.InputError` naming the table, the row and what is wrong.

Checked: ``keypoints``, ``matches`` and ``two_view_geometries`` rows have ``rows >= 0``, a usable ``cols``
(keypoints 2, 4 or 6 float32 columns; inlier matches 2 uint32 columns) and a blob of exactly
``rows * cols * 4`` bytes; every two-view geometry's pair id names two images of the
``images`` table (COLMAP's ``pair_id = 2147483647 * image_id1 + image_id2``, ``id1 < id2``).
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

from pipeline.errors import InputError

__all__ = ["MAX_PAIR_ID_IMAGE", "check_database_tables"]

#: COLMAP's pair id base (``kMaxNumImages``)
MAX_PAIR_ID_IMAGE = 2147483647


def _rows(con, sql):
    try:
        return con.execute(sql).fetchall()
    except sqlite3.DatabaseError as exc:
        raise InputError(f"cannot read the COLMAP tables ({exc})") from None


def _check_matrix_rows(path: Path, table: str, key: str, rows, allowed_cols) -> None:
    for ident, r, c, nbytes in rows:
        where = f"database {str(path)!r}, table {table}, {key} {ident}"
        if not isinstance(r, int) or not isinstance(c, int) or r < 0 or c < 0:
            raise InputError(f"{where}: rows={r!r}, cols={c!r} are not non-negative integers; "
                             "the database is corrupt (rebuild it with COLMAP)")
        if r and c not in allowed_cols:
            raise InputError(f"{where}: {c} columns, expected {' or '.join(map(str, allowed_cols))}"
                             "; the database is corrupt (rebuild it with COLMAP)")
        if (nbytes or 0) != r * c * 4:
            raise InputError(f"{where}: rows={r}, cols={c} need {r * c * 4} bytes of data but "
                             f"{nbytes or 0} are stored; the database is corrupt (rebuild it "
                             "with COLMAP)")


def check_database_tables(path: str | Path, shown: str | Path | None = None) -> None:
    """Raise InputError on the first inconsistent row (module docstring); read only.

    Parameters
    ----------
    path : SQLite file (a private copy: it is opened read only anyway)
    shown : the name to give in messages (the user's file), default ``path``
    """
    con = sqlite3.connect(f"file:{Path(path)}?mode=ro", uri=True)
    path = Path(shown if shown is not None else path)
    try:
        tables = {r[0] for r in _rows(con, "SELECT name FROM sqlite_master WHERE type='table'")}
        missing = {"images", "keypoints", "two_view_geometries"} - tables
        if missing:
            raise InputError(f"database {str(path)!r} has no {', '.join(sorted(missing))} "
                             "table(s); it is not a COLMAP database")
        images = {r[0] for r in _rows(con, "SELECT image_id FROM images")}
        _check_matrix_rows(path, "keypoints", "image_id", _rows(
            con, "SELECT image_id, rows, cols, length(data) FROM keypoints"), (2, 4, 6))
        tvg = _rows(con, "SELECT pair_id, rows, cols, length(data) FROM two_view_geometries")
        _check_matrix_rows(path, "two_view_geometries", "pair_id", tvg, (2,))
        if "matches" in tables:
            _check_matrix_rows(path, "matches", "pair_id", _rows(
                con, "SELECT pair_id, rows, cols, length(data) FROM matches"), (2,))
        for pair_id, *_ in tvg:
            id1, id2 = divmod(int(pair_id), MAX_PAIR_ID_IMAGE)
            for iid in (id1, id2):
                if iid not in images:
                    raise InputError(
                        f"database {str(path)!r}, table two_view_geometries, pair_id {pair_id}: "
                        f"names image_id {iid}, which is not in the images table; the database "
                        "is inconsistent (rebuild it with COLMAP)")
    finally:
        con.close()
