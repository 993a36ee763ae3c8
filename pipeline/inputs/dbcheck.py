"""Sanity checks of a COLMAP database's tables before pycolmap reads them.

pycolmap trusts the ``rows``/``cols`` columns of its tables: a negative ``rows`` makes it
allocate without bound (``std::bad_alloc``) and a pair id naming an image that does not
exist surfaces later as a KeyError. A database is a file a user (or an attacker) hands us, so
it is read here first with :mod:`sqlite3` (read only) and every problem becomes one
:class:`~pipeline.errors.InputError` naming the table, the row and what is wrong.

Checked: ``keypoints``, ``matches`` and ``two_view_geometries`` rows have ``rows >= 0``, a usable ``cols``
(keypoints 2, 4 or 6 float32 columns; inlier matches 2 uint32 columns) and a blob of exactly
``rows * cols * 4`` bytes; image ids and pair ids are stored as integers (not text, real
numbers or blobs); every image's ``camera_id`` is a row of the ``cameras`` table (COLMAP's
mapper stops on an image without its camera; a database without that table has none); where
the ``frames`` table holds frames, every image is a camera of a frame that exists, of a rig
that has that camera (:func:`_check_frames`), and every camera of a rig is in the ``cameras``
table (:func:`_check_rigs`); a pose prior's matrices have their sizes
(:func:`_check_pose_priors`); a pair id appears once and names two different
images of the ``images`` table (COLMAP's ``pair_id = 2147483647 * image_id1 + image_id2``; a row stored with the two
images the other way round is read in its own orientation).

The user's file is opened through SQLite, read only (:func:`open_readonly`), so changes
another program still holds in its write-ahead log are read too.
"""

from __future__ import annotations

import os
import sqlite3
from collections import Counter
from pathlib import Path

from pipeline.errors import InputError

__all__ = ["MAX_PAIR_ID_IMAGE", "DatabaseSizes", "check_database_tables", "open_readonly"]

#: COLMAP's pair id base (``kMaxNumImages``)
MAX_PAIR_ID_IMAGE = 2147483647


def open_readonly(path: str | os.PathLike) -> sqlite3.Connection:
    """A read-only SQLite connection to the user's database ``path``.

    With a write-ahead log (``-wal``) or a rollback journal beside it (another program has it
    open, or stopped while writing) it is opened ``mode=ro``: SQLite reads the committed
    changes still in the log. Without one it is opened ``immutable=1``, which creates no
    side file beside it.
    """
    path = Path(path)
    side = any(os.path.lexists(f"{path}{s}") for s in ("-wal", "-journal"))
    uri = f"{path.resolve().as_uri()}?{'mode=ro' if side else 'immutable=1'}"
    try:
        return sqlite3.connect(uri, uri=True)
    except sqlite3.Error as exc:
        raise InputError(f"database {str(path)!r} cannot be opened ({exc})") from None


def _utf8(data: bytes) -> bool:
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def _rows(con, sql, path: Path):
    try:
        return con.execute(sql).fetchall()
    except sqlite3.DatabaseError as exc:
        raise InputError(f"database {str(path)!r}: cannot read its COLMAP tables ({exc}); "
                         "give a database made by COLMAP or hloc") from None


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


class DatabaseSizes(dict):
    """What the tables declare, counted before anything is read: ``images``,
    ``keypoint_bytes`` (float32 keypoint data), ``inliers`` (verified matches)."""


def _integer_ids(path: Path, table: str, column: str, rows) -> None:
    for value, kind in rows:
        if kind != "integer":
            shown = repr(value)
            shown = shown if len(shown) <= 40 else shown[:37] + "..."
            raise InputError(
                f"database {str(path)!r}, table {table}: {column} {shown} is stored as {kind}, "
                "not an integer; COLMAP stores integer ids: the database is corrupt (rebuild "
                "it with COLMAP)")


#: ``sensor_type`` of a camera in the ``rigs``, ``rig_sensors`` and ``frame_data`` tables
#: (COLMAP's ``SensorType::CAMERA``)
CAMERA_SENSOR = 0


def _check_rigs(con, path: Path, tables: set[str], cameras: set) -> None:
    """InputError for a rig whose camera (its reference sensor, or one of ``rig_sensors``) the
    cameras table lacks: COLMAP's mapper stops on it (``Camera 2 from rig 1 not found``)."""
    named = []
    if "rigs" in tables:
        named += [("rigs", rig_id, sensor_id) for rig_id, sensor_id in _rows(
            con, f"SELECT rig_id, ref_sensor_id FROM rigs WHERE ref_sensor_type = {CAMERA_SENSOR}"
                 " ORDER BY rig_id", path)]
    if "rig_sensors" in tables:
        named += [("rig_sensors", rig_id, sensor_id) for rig_id, sensor_id in _rows(
            con, "SELECT rig_id, sensor_id FROM rig_sensors WHERE sensor_type = "
                 f"{CAMERA_SENSOR} ORDER BY rig_id, sensor_id", path)]
    for table, rig_id, sensor_id in named:
        if sensor_id not in cameras:
            raise InputError(f"database {str(path)!r}, table {table}, rig_id {rig_id}: names "
                             f"camera {sensor_id!r}, which is not in the cameras table; the "
                             "database is inconsistent (rebuild it with COLMAP)")


def _check_frames(con, path: Path, tables: set[str]) -> None:
    """InputError for an image that COLMAP's mapper finds in no frame, or in a frame of no
    such frame, or of a rig without its camera (``Check failed: image.HasFrameId()``,
    ``Frame with ID F does not exist``, ``rig.HasSensor``). A database without frames (an
    older COLMAP's, or one whose frames were removed) is fine: COLMAP gives each image a
    frame of its own."""
    frames = dict(_rows(con, "SELECT frame_id, rig_id FROM frames", path)) \
        if "frames" in tables else {}
    if not frames:
        return
    data = _rows(con, "SELECT data_id, frame_id, sensor_id FROM frame_data WHERE sensor_type = "
                      f"{CAMERA_SENSOR}", path) if "frame_data" in tables else []
    frame_of = {data_id: (frame_id, sensor_id) for data_id, frame_id, sensor_id in data}
    sensors: dict[int, set] = {}
    if "rigs" in tables:
        for rig_id, sensor_id in _rows(con, "SELECT rig_id, ref_sensor_id FROM rigs WHERE "
                                            f"ref_sensor_type = {CAMERA_SENSOR}", path):
            sensors.setdefault(rig_id, set()).add(sensor_id)
    if "rig_sensors" in tables:
        for rig_id, sensor_id in _rows(con, "SELECT rig_id, sensor_id FROM rig_sensors WHERE "
                                            f"sensor_type = {CAMERA_SENSOR}", path):
            sensors.setdefault(rig_id, set()).add(sensor_id)
    for image_id, name in _rows(con, "SELECT image_id, name FROM images ORDER BY image_id",
                                path):
        where = f"database {str(path)!r}, table images, image_id {image_id} ({name!r})"
        if image_id not in frame_of:
            raise InputError(f"{where}: in no frame (table frame_data has no camera row with "
                             f"data_id {image_id}), though the frames table holds "
                             f"{len(frames)} frame(s); the database is inconsistent (rebuild "
                             "it with COLMAP)")
        frame_id, sensor_id = frame_of[image_id]
        if frame_id not in frames:
            raise InputError(f"{where}: table frame_data puts it in frame_id {frame_id!r}, "
                             "which is not in the frames table; the database is inconsistent "
                             "(rebuild it with COLMAP)")
        rig_id = frames[frame_id]
        if rig_id in sensors and sensor_id not in sensors[rig_id]:
            raise InputError(f"{where}: table frame_data gives it camera {sensor_id!r} of "
                             f"frame {frame_id}, whose rig {rig_id} has no such camera (tables "
                             "rigs, rig_sensors); the database is inconsistent (rebuild it "
                             "with COLMAP)")


#: bytes of each matrix column of the ``pose_priors`` table (float64: a position, its 3 x 3
#: covariance, a gravity direction); COLMAP's mapper reads them and stops on another size
POSE_PRIOR_BYTES = {"position": 3 * 8, "position_covariance": 9 * 8, "gravity": 3 * 8}


def _check_pose_priors(con, path: Path) -> None:
    """InputError for a ``pose_priors`` matrix (:data:`POSE_PRIOR_BYTES`) stored with another
    size than its values need (NULL: none stored, as COLMAP writes an unknown one)."""
    columns = [r[1] for r in _rows(con, "PRAGMA table_info(pose_priors)", path)]
    key = "pose_prior_id" if "pose_prior_id" in columns else "rowid"
    for column, size in POSE_PRIOR_BYTES.items():
        if column not in columns:
            continue
        bad = _rows(con, f"SELECT {key}, length({column}) FROM pose_priors WHERE {column} IS NOT "
                         f"NULL AND length({column}) != {size} LIMIT 1", path)
        if bad:
            raise InputError(f"database {str(path)!r}, table pose_priors, {key} {bad[0][0]}: "
                             f"{column} holds {bad[0][1]} bytes, expected {size} ({size // 8} "
                             "float64 values) or NULL; the database is corrupt (rebuild it with "
                             "COLMAP, or delete that row)")


def check_database_tables(con: sqlite3.Connection, path: str | Path) -> DatabaseSizes:
    """Raise InputError on the first inconsistent row (module docstring); read only.

    Parameters
    ----------
    con : a connection to the database (:func:`open_readonly`, or a private copy)
    path : the name to give in messages (the user's file)

    Returns
    -------
    DatabaseSizes — what the tables hold, for the memory estimate of reading them
    """
    path = Path(path)
    tables = {r[0] for r in _rows(con, "SELECT name FROM sqlite_master WHERE type='table'",
                                  path)}
    missing = {"images", "keypoints", "two_view_geometries"} - tables
    if missing:
        raise InputError(f"database {str(path)!r} has no {', '.join(sorted(missing))} "
                         "table(s); it is not a COLMAP database")
    _integer_ids(path, "images", "image_id",
                 _rows(con, "SELECT image_id, typeof(image_id) FROM images", path))
    _integer_ids(path, "keypoints", "image_id",
                 _rows(con, "SELECT image_id, typeof(image_id) FROM keypoints", path))
    _integer_ids(path, "two_view_geometries", "pair_id",
                 _rows(con, "SELECT pair_id, typeof(pair_id) FROM two_view_geometries", path))
    images = {r[0] for r in _rows(con, "SELECT image_id FROM images", path)}
    # a database without the cameras table has none of its images' cameras either
    cameras = {r[0] for r in _rows(con, "SELECT camera_id FROM cameras", path)} \
        if "cameras" in tables else set()
    for image_id, name, camera_id in _rows(
            con, "SELECT image_id, name, camera_id FROM images ORDER BY image_id", path):
        if isinstance(name, bytes) and not _utf8(name):  # stored as a BLOB: not text
            raise InputError(f"database {str(path)!r}, table images, image_id {image_id}: "
                             f"name {name!r} is not UTF-8 text; the database is corrupt "
                             "(rebuild it with COLMAP)")
        if camera_id not in cameras:
            lacks = "which is not in the cameras table" if "cameras" in tables else \
                "but the database has no cameras table"
            raise InputError(f"database {str(path)!r}, table images, image_id {image_id} "
                             f"({name!r}): names camera_id {camera_id!r}, {lacks}; the "
                             "database is inconsistent (rebuild it with COLMAP)")
    _check_rigs(con, path, tables, cameras)
    _check_frames(con, path, tables)
    if "pose_priors" in tables:
        _check_pose_priors(con, path)
    kp = _rows(con, "SELECT image_id, rows, cols, length(data) FROM keypoints", path)
    _check_matrix_rows(path, "keypoints", "image_id", kp, (2, 4, 6))
    tvg = _rows(con, "SELECT pair_id, rows, cols, length(data) FROM two_view_geometries", path)
    _check_matrix_rows(path, "two_view_geometries", "pair_id", tvg, (2,))
    if "matches" in tables:
        _check_matrix_rows(path, "matches", "pair_id", _rows(
            con, "SELECT pair_id, rows, cols, length(data) FROM matches", path), (2,))
    twice = [(p, k) for p, k in Counter(r[0] for r in tvg).items() if k > 1]
    if twice:
        raise InputError(f"database {str(path)!r}, table two_view_geometries: pair_id "
                         f"{twice[0][0]} is stored in {twice[0][1]} rows; a pair has one row: "
                         "the database is inconsistent (rebuild it with COLMAP)")
    for pair_id, *_ in tvg:
        id1, id2 = divmod(int(pair_id), MAX_PAIR_ID_IMAGE)
        where = f"database {str(path)!r}, table two_view_geometries, pair_id {pair_id}"
        for iid in (id1, id2):
            if iid not in images:
                raise InputError(f"{where}: names image_id {iid}, which is not in the images "
                                 "table; the database is inconsistent (rebuild it with COLMAP)")
        if id1 == id2:
            raise InputError(f"{where}: pairs image_id {id1} with itself; the database is "
                             "inconsistent (rebuild it with COLMAP)")
    return DatabaseSizes(images=len(images), keypoint_bytes=sum(r * c * 4 for _, r, c, _ in kp),
                         inliers=sum(r for _, r, _, _ in tvg))
