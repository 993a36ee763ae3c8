"""COLMAP databases: write the pipeline's matches into one, read COLMAP's or hloc's back.

- :func:`write_database` — views + features + links as a COLMAP database: cameras, trivial
  rigs and frames (COLMAP >= 3.12), keypoints, the matches table (every link matching
  produced) and the two-view geometries (the verified links to map with, e.g. the links kept
  by the consistency stage, Aragüés et al. Alg. 1).
- :func:`read_database` — keypoints and two-view geometries of a database made by COLMAP or
  hloc, as the pipeline's :class:`~pipeline.types.Links`.
- :func:`write_cleaned_database` — a copy of a database with some two-view-geometry inliers
  removed; the input file is never opened for writing.
- :func:`relative_rotations` — each verified pair's relative rotation from its two-view
  geometry (the loop check of ``clean-db --loop-check``, :mod:`pipeline.matching.loops`).

A user's database is read through SQLite, never by copying its bytes: its tables are checked
first (:mod:`pipeline.inputs.dbcheck`), then ``VACUUM INTO`` takes a consistent private snapshot of
it (with the changes still in its write-ahead log), which pycolmap reads and from which the
cleaned copy is made.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import weakref
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from pipeline.colmap.base import COLMAP_PIXEL_OFFSET, quiet_colmap
from pipeline.errors import InputError
from pipeline.inputs.dbcheck import MAX_PAIR_ID_IMAGE, check_database_tables, open_readonly
from pipeline.runfolder import make_scratch_folder
from pipeline.types import Features, Links, View

__all__ = ["DatabaseContents", "calibrated", "check_database_file", "write_database",
           "read_database", "write_cleaned_database", "relative_rotations", "rescale_database"]

_TVG = pycolmap.TwoViewGeometryConfiguration


@contextmanager
def _atomic_database(path: Path, copy_from: Path | None = None):
    """Yield a temporary database path next to ``path``; renamed onto ``path`` on success.

    With ``copy_from`` the temporary file starts as a copy of that database. On failure the
    temporary file and its SQLite side files are removed, so no half-written database is left.
    """
    from pipeline.runfolder import publish_mode

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".db", dir=path.parent)
    os.close(fd)
    try:
        if copy_from is not None:
            shutil.copyfile(copy_from, tmp)
        else:
            os.unlink(tmp)  # COLMAP creates the file itself
        yield tmp
        publish_mode(tmp, directory=False)
        os.replace(tmp, path)
    except BaseException:
        for leftover in (tmp, tmp + "-wal", tmp + "-shm", tmp + "-journal"):
            if os.path.exists(leftover):
                os.unlink(leftover)
        raise


# ------------------------------------------------------------------------------------- writing

def calibrated(view: View) -> bool:
    """True when ``view.K`` is a calibration (K.txt, rendered views), not an EXIF estimate or
    a guess; the mapper then keeps it fixed (:func:`incremental_mapping`)."""
    return bool(view.intrinsics_known) and not view.intrinsics_source.startswith("exif")


def _camera(view: View) -> pycolmap.Camera:
    """COLMAP camera of a view.

    - a rendered view (a pinhole by construction, ``intrinsics_source`` empty): ``PINHOLE``
      (fx, fy, cx, cy);
    - a photograph: ``SIMPLE_RADIAL`` (f, cx, cy, k), COLMAP's own model for photographs,
      ``f = sqrt(fx fy)``, ``k = 0`` to start. Real lenses are not pinholes: on the Sceaux
      photographs a fixed pinhole K.txt left 0.86 px of reprojection error and a fifth fewer
      points than COLMAP's refined radial term. A calibrated photograph (K.txt) keeps its
      focal length in the bundle adjustments, the radial term is refined
      (:func:`pipeline.colmap.mapping.incremental_mapping`); EXIF and guessed focal lengths are
      refined, one focal length because two drift apart on few views.
    """
    K = np.asarray(view.K, dtype=np.float64)
    w, h = view.size
    cx, cy = K[0, 2] + COLMAP_PIXEL_OFFSET, K[1, 2] + COLMAP_PIXEL_OFFSET
    if calibrated(view) and not view.intrinsics_source:
        cam = pycolmap.Camera(model="PINHOLE", width=w, height=h, params=[K[0, 0], K[1, 1], cx, cy])
    else:
        cam = pycolmap.Camera(model="SIMPLE_RADIAL", width=w, height=h,
                              params=[float(np.sqrt(K[0, 0] * K[1, 1])), cx, cy, 0.0])
    # an EXIF focal length is a prior; a guess is not
    cam.has_prior_focal_length = bool(view.intrinsics_known)
    return cam


def _camera_key(cam: pycolmap.Camera) -> tuple:
    return (str(cam.model), int(cam.width), int(cam.height),
            tuple(float(p) for p in cam.params), bool(cam.has_prior_focal_length))


def _write_image_with_trivial_rig(db, view: View, shared: dict | None = None,
                                  file_size: tuple[int, int] | None = None) -> int:
    """Camera, one-sensor rig, image and frame, as COLMAP's feature extractor writes them.

    ``shared`` maps a camera (model, size, parameters) and ``file_size`` to its
    ``(camera_id, rig_id)``: images with identical intrinsics share one camera and its rig
    (COLMAP's ``single_camera``), so one K (e.g. a K.txt) is one camera in the database and in
    ``sparse/``; images downscaled from files of different sizes do not (a camera is scaled
    back to its files by one factor, :func:`rescale_database`).
    """
    cam = _camera(view)
    key = (_camera_key(cam), file_size)
    if shared is not None and key in shared:
        camera_id, rig_id = shared[key]
        sensor = pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=camera_id)
    else:
        camera_id = db.write_camera(cam)
        sensor = pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=camera_id)
        rig = pycolmap.Rig()
        rig.add_ref_sensor(sensor)
        rig_id = db.write_rig(rig)
        if shared is not None:
            shared[key] = (camera_id, rig_id)
    image_id = db.write_image(pycolmap.Image(name=view.name, camera_id=camera_id))
    frame = pycolmap.Frame()
    frame.rig_id = rig_id
    frame.add_data_id(pycolmap.data_t(sensor_id=sensor, id=image_id))
    db.write_frame(frame)
    return image_id


def _fundamental(x1: np.ndarray, x2: np.ndarray) -> np.ndarray | None:
    """Least-squares 8-point F (``x2^T F x1 = 0``) on already verified matches, or None."""
    import cv2

    if len(x1) < 8:
        return None
    F, _ = cv2.findFundamentalMat(x1.astype(np.float64), x2.astype(np.float64), cv2.FM_8POINT)
    if F is None or F.shape != (3, 3):
        return None
    return F


def _two_view_geometry(pairs: np.ndarray, view_i: View, view_j: View, kp_i: np.ndarray,
                       kp_j: np.ndarray) -> pycolmap.TwoViewGeometry:
    """Two-view geometry whose inliers are ``pairs`` (the verified links of the pair).

    ``F`` is re-fitted to those links (our matcher keeps the RANSAC inliers, not the model);
    with both intrinsics known the pair is ``CALIBRATED`` with ``E = K_j^T F K_i``. COLMAP's
    mapper uses only the inliers (it re-estimates the initial pair's pose itself).
    """
    inliers = np.ascontiguousarray(pairs, dtype=np.uint32).reshape(-1, 2)
    F = _fundamental(kp_i[pairs[:, 0]] + COLMAP_PIXEL_OFFSET,
                     kp_j[pairs[:, 1]] + COLMAP_PIXEL_OFFSET) if len(pairs) else None
    if F is None:
        return pycolmap.TwoViewGeometry(config=_TVG.UNCALIBRATED, inlier_matches=inliers)
    if view_i.intrinsics_known and view_j.intrinsics_known:
        Ki = _camera(view_i).calibration_matrix()
        Kj = _camera(view_j).calibration_matrix()
        return pycolmap.TwoViewGeometry(config=_TVG.CALIBRATED, F=F, E=Kj.T @ F @ Ki,
                                        inlier_matches=inliers)
    return pycolmap.TwoViewGeometry(config=_TVG.UNCALIBRATED, F=F, inlier_matches=inliers)


def _group_by_pair(a, b, fa, fb) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]:
    """``{(a, b): (fa, fb) of the rows with that pair}``, input order kept within a pair."""
    a, b = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64)
    if a.size == 0:
        return {}
    order = np.lexsort((b, a))
    a, b, fa, fb = a[order], b[order], np.asarray(fa)[order], np.asarray(fb)[order]
    starts = np.flatnonzero(np.r_[True, (a[1:] != a[:-1]) | (b[1:] != b[:-1])])
    ends = np.r_[starts[1:], len(a)]
    return {(int(a[s]), int(b[s])): (fa[s:e], fb[s:e]) for s, e in zip(starts, ends, strict=True)}


def _pairs_by_edge(links: Links) -> dict[tuple[int, int], np.ndarray]:
    """Group links by camera pair: ``{(i, j): (M, 2) feature pairs}``."""
    return {k: np.stack(v, axis=1) for k, v in
            _group_by_pair(links.cam_i, links.cam_j, links.feat_i, links.feat_j).items()}


def write_database(path: str | Path, views: list[View], features: list[Features], links: Links,
                   keep: np.ndarray | None = None,
                   file_sizes: list[tuple[int, int]] | None = None) -> Path:
    """Write views, keypoints and links as a new COLMAP database.

    Parameters
    ----------
    path : the ``.db`` file to create; it must not exist (a database is never overwritten)
    views : list[View], (n,) — names, sizes and intrinsics (PINHOLE cameras)
    features : list[Features], (n,) — keypoints (OpenCV convention, written with ``+0.5``);
        descriptors are not written (the database is for mapping, not for re-matching)
    links : Links, (L,) — written to the ``matches`` table
    keep : ndarray, (L,) bool or None — links written as two-view-geometry inliers (``None``:
        all). ``keep = ~deleted`` gives the database of the cleaned association.
    file_sizes : list of (width, height), (n,), or None — the size of each view's image file
        when the views are downscaled copies: views of files of different sizes never share a
        camera

    Returns
    -------
    path : Path of the database, written atomically (temp file, then rename)

    Notes
    -----
    Image ``i`` gets image id ``i + 1``; images with identical intrinsics (model, size,
    parameters) share one camera and its trivial rig, each image has its own frame. Pairs with links get a two-view geometry, even when none of
    their links is kept (then with no inliers, COLMAP's own way of saying "not verified").
    """
    path = Path(path)
    if len(views) != len(features):
        raise InputError(f"write_database: {len(views)} views but {len(features)} feature sets")
    if path.exists():
        raise InputError(f"database {str(path)!r} already exists; choose a new file name")
    keep = np.ones(len(links), dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    if keep.shape != (len(links),):
        raise InputError(f"write_database: keep has shape {keep.shape}, expected ({len(links)},)")
    with _atomic_database(path) as tmp, quiet_colmap(), pycolmap.Database.open(tmp) as db:
        shared: dict = {}
        sizes = [None] * len(views) if file_sizes is None else [tuple(s) for s in file_sizes]
        image_ids = [_write_image_with_trivial_rig(db, v, shared, size)
                     for v, size in zip(views, sizes, strict=True)]
        for image_id, f in zip(image_ids, features, strict=True):
            kp = np.asarray(f.keypoints, dtype=np.float32).reshape(-1, 2)
            db.write_keypoints(image_id, kp + np.float32(COLMAP_PIXEL_OFFSET))
        all_pairs = _pairs_by_edge(links)
        kept_pairs = _pairs_by_edge(links.subset(keep))
        empty = np.zeros((0, 2), dtype=np.int64)
        for (i, j), pairs in all_pairs.items():
            db.write_matches(image_ids[i], image_ids[j],
                             np.ascontiguousarray(pairs, dtype=np.uint32))
            tvg = _two_view_geometry(kept_pairs.get((i, j), empty), views[i], views[j],
                                     features[i].keypoints, features[j].keypoints)
            db.write_two_view_geometry(image_ids[i], image_ids[j], tvg)
    return path


def rescale_database(path: str | Path, sizes: dict[str, tuple[int, int]]) -> Path:
    """Scale a database written at the downscaled size of the images to their files, in place.

    ``sizes``: ``{image name: (width, height)}`` of the files. As
    :func:`pipeline.colmap.mapping.rescale_to_files` scales a model: in COLMAP's pixel
    convention (origin at the top-left corner) resizing by ``(sx, sy)`` multiplies every pixel
    coordinate, so each camera is rescaled (``Camera.rescale``, once for a shared camera) and
    each image's keypoints are multiplied; a pair's fundamental matrix becomes
    ``S_j⁻ᵀ F S_i⁻¹`` and its homography ``S_j H S_i⁻¹`` (``S = diag(sx, sy, 1)``), so that
    ``x_jᵀ F x_i = 0`` holds for the scaled points; the essential matrix, the relative pose and
    the inlier matches do not change. Images not named in ``sizes`` keep their size.
    """
    path = Path(path)
    with quiet_colmap(), pycolmap.Database.open(str(path)) as db:
        images = {im.image_id: im for im in db.read_all_images()}
        cameras = {c.camera_id: c for c in db.read_all_cameras()}
        factor: dict[int, tuple[float, float]] = {}
        for im in images.values():
            if im.name not in sizes or im.camera_id in factor:
                continue
            cam = cameras[im.camera_id]
            W, H = (int(v) for v in sizes[im.name])
            factor[im.camera_id] = (W / cam.width, H / cam.height)
            if (W, H) != (cam.width, cam.height):
                cam.rescale(W, H)
                db.update_camera(cam)
        S = {i: np.diag([*factor.get(im.camera_id, (1.0, 1.0)), 1.0])
             for i, im in images.items()}
        for i in images:
            if S[i][0, 0] == 1.0 and S[i][1, 1] == 1.0 or not db.exists_keypoints(i):
                continue
            kp = np.array(db.read_keypoints(i), dtype=np.float32)
            kp[:, 0] *= np.float32(S[i][0, 0])
            kp[:, 1] *= np.float32(S[i][1, 1])
            db.update_keypoints(i, kp)
        pair_ids, geometries = db.read_two_view_geometries()
        for pid, g in zip(pair_ids, geometries, strict=True):
            i, j = pycolmap.pair_id_to_image_pair(pid)
            Si, Sj = S[i], S[j]
            if np.array_equal(Si, Sj) and Si[0, 0] == 1.0 and Si[1, 1] == 1.0:
                continue
            if g.F is not None:  # None: the geometry has none
                g.F = np.linalg.inv(Sj).T @ np.asarray(g.F) @ np.linalg.inv(Si)
            if g.H is not None:
                g.H = Sj @ np.asarray(g.H) @ np.linalg.inv(Si)
            db.update_two_view_geometry(i, j, g)
    return path


# ------------------------------------------------------------------------------------- reading

@dataclass
class DatabaseContents:
    """The verified matches of a COLMAP database in the pipeline's terms.

    Attributes
    ----------
    path : Path — the database read
    names : list[str], (n,) — image names; camera ``i`` is the ``i``-th name in sorted order
    image_ids : ndarray, (n,) int64 — COLMAP image id of each camera
    keypoints : list[ndarray], (n,) each (m_i, 2) float32 — OpenCV pixel convention
    links : Links, (L,) — two-view-geometry inliers, each undirected link once, ``cam_i < cam_j``
    not_one_to_one : ndarray, (L,) bool — a link whose feature is linked to two features or
        more of the same other image by the inliers of that pair (COLMAP allows this when
        cross-check is off; the paper's Assumption 2.2 does not): every such link, since the
        database holds no score to tell which one is right
    link_pair_id : ndarray, (L,) int64 — the ``pair_id`` of the two-view-geometry row holding
        each link, as stored (its links are in the row's inlier order)
    snapshot : Path or None — the private snapshot of the database that was read (kept while
        this object lives; the cleaned copy is made from it)
    pairs_without_inliers : int — two-view geometries with no inliers (failed verification)
    watermark_pairs_ignored : int — pairs with inliers left out as ``WATERMARK`` (read with
        ``ignore_watermarks``; 0 otherwise)
    fundamental : dict ``(i, j) -> (3, 3)`` — the pair's fundamental matrix in OpenCV pixels
        (``x_jᵀ F x_i = 0``), ``i < j``, for the pairs whose geometry has one
    """

    path: Path
    names: list[str]
    image_ids: np.ndarray
    keypoints: list[np.ndarray]
    links: Links
    not_one_to_one: np.ndarray
    pairs_without_inliers: int = 0
    watermark_pairs_ignored: int = 0
    fundamental: dict = field(default_factory=dict)
    cameras: list = field(default_factory=list)
    link_pair_id: np.ndarray | None = None
    snapshot: Path | None = None
    _snapshot_dir: object = field(default=None, repr=False)

    @property
    def features_per_camera(self) -> np.ndarray:
        """Keypoints per camera, ``(n,)``."""
        return np.array([len(k) for k in self.keypoints], dtype=np.int64)

    def close(self) -> None:
        """Remove the private snapshot (also done when the object is collected)."""
        if self._snapshot_dir is not None:
            self._snapshot_dir()  # runs the removal once
            self._snapshot_dir, self.snapshot = None, None


def _repeated(key: np.ndarray) -> np.ndarray:
    """``(L,)`` bool: True where ``key`` appears more than once."""
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    return counts[inverse.reshape(-1)] > 1


def _xy(keypoints) -> np.ndarray:
    """``(m, 2)`` OpenCV-convention positions from COLMAP keypoint rows ``(m, 2|4|6)``."""
    kp = np.asarray(keypoints, dtype=np.float32)
    if kp.size == 0:
        return np.zeros((0, 2), dtype=np.float32)
    return np.ascontiguousarray(kp[:, :2] - np.float32(COLMAP_PIXEL_OFFSET))


def check_database_file(path: Path) -> None:
    """InputError unless ``path`` is an existing regular file starting as an SQLite file
    (a folder, a FIFO or a device is named as such, never opened for reading)."""
    from pipeline.outputs import require_input_file

    require_input_file(path, "database")
    with open(path, "rb") as fh:
        if fh.read(16) != b"SQLite format 3\x00":
            raise InputError(f"{str(path)!r} is not a COLMAP database (not an SQLite file)")


def read_database(path: str | Path, check_sizes=None, *,
                  ignore_watermarks: bool = False) -> DatabaseContents:
    """Read keypoints and two-view geometries from a COLMAP database (COLMAP or hloc made).

    Parameters
    ----------
    path : the ``.db`` file; read through SQLite, read only (see the module notes)
    check_sizes : called with the :class:`~pipeline.inputs.dbcheck.DatabaseSizes` the tables
        declare before anything is copied or read (e.g. a memory guard that raises)
    ignore_watermarks : read the pairs as COLMAP's mapper does with its ``ignore_watermarks``
        option on: the two-view geometries of configuration ``WATERMARK`` (and only those)
        give no links; their number is ``watermark_pairs_ignored``. COLMAP's source,
        ``src/colmap/scene/database_cache.cc`` (``DatabaseCache`` loading, which builds the
        mapper's correspondence graph): a pair is used when its inliers reach
        ``min_num_matches`` and ``!ignore_watermarks || config != TwoViewGeometry::WATERMARK``;
        ``DEGENERATE``, ``UNDEFINED`` and every other configuration are used either way

    Returns
    -------
    DatabaseContents

    Raises
    ------
    InputError
        Missing file, not an SQLite/COLMAP database, inconsistent tables, fewer than two
        images, or no two-view geometries (run COLMAP's matcher, or hloc's geometric
        verification, first).
    """
    import sqlite3

    path = Path(path)
    check_database_file(path)
    con = open_readonly(path)
    snapshot_dir = None
    try:
        try:
            sizes = check_database_tables(con, path)
            if check_sizes is not None:
                check_sizes(sizes)
            snapshot_dir = make_scratch_folder("colmap-read-")
            copy = Path(snapshot_dir) / "read.db"
            try:
                con.execute("VACUUM INTO ?", (str(copy),))
            except sqlite3.Error as exc:
                raise InputError(f"database {str(path)!r} cannot be read ({exc})") from None
        finally:
            con.close()
        snap = sqlite3.connect(copy)
        try:
            check_database_tables(snap, path)  # what pycolmap reads is what was checked
        finally:
            snap.close()
        try:
            with quiet_colmap(), pycolmap.Database.open(copy) as db:
                images = db.read_all_images()
                keypoints = {im.image_id: db.read_keypoints(im.image_id)
                             if db.exists_keypoints(im.image_id) else np.zeros((0, 2), np.float32)
                             for im in images}
                pair_ids, geometries = db.read_two_view_geometries()
                # rows without inliers may be left out of the read above; count them all
                n_rows = db.num_verified_image_pairs()
                raw = (db.num_matches(), db.num_matched_image_pairs())
                cameras = {c.camera_id: c for c in db.read_all_cameras()}
        except (RuntimeError, ValueError, IndexError) as exc:
            raise InputError(f"{str(path)!r} could not be read as a COLMAP database ({exc})") from None
        except MemoryError as exc:
            # the tables' declared sizes passed check_sizes: COLMAP's reader was asked for
            # more by a value it sizes a buffer from (e.g. a two_view_geometries camera1 or
            # camera2 blob of a few bytes, or of another type)
            raise InputError(f"{str(path)!r} could not be read as a COLMAP database (out of "
                             f"memory: {exc or 'MemoryError'}): a value of its tables asks "
                             "COLMAP's reader for more memory than the machine has, so the "
                             "database is corrupt (rebuild it with COLMAP)") from None
        contents = _contents(path, images, keypoints, pair_ids, geometries, n_rows, cameras,
                             raw, ignore_watermarks=ignore_watermarks)
    except BaseException:
        # any way out before the contents own it (an error, a Ctrl-C or a SIGTERM while the
        # snapshot is taken) removes the snapshot
        if snapshot_dir is not None:
            shutil.rmtree(snapshot_dir, ignore_errors=True)
        raise
    contents.snapshot = copy
    contents._snapshot_dir = weakref.finalize(contents, shutil.rmtree, snapshot_dir, True)
    return contents


def _contents(path: Path, images, keypoints, pair_ids, geometries, n_rows: int,
              cameras, raw: tuple[int, int] = (0, 0), *,
              ignore_watermarks: bool = False) -> DatabaseContents:
    """The contents read; ``raw``: the matches table's ``(matches, image pairs)``, named
    when no pair is verified (matched with geometric verification skipped);
    ``ignore_watermarks``: as :func:`read_database`."""
    if len(images) < 2:
        raise InputError(f"database {str(path)!r} holds {len(images)} image(s); at least two are needed")
    images = sorted(images, key=lambda im: im.name)
    names = [im.name for im in images]
    image_ids = np.array([im.image_id for im in images], dtype=np.int64)
    cam_of_id = {int(iid): k for k, iid in enumerate(image_ids)}
    for im in images:
        _check_keypoints(path, im.name, keypoints[im.image_id], cameras.get(im.camera_id))
    kps = [_xy(keypoints[im.image_id]) for im in images]
    usable = [(pid, g) for pid, g in zip(pair_ids, geometries, strict=True)
              if len(g.inlier_matches)]
    watermarks = 0
    if ignore_watermarks:
        with_inliers = len(usable)
        usable = [(pid, g) for pid, g in usable if g.config != _TVG.WATERMARK]
        # every pair with inliers a WATERMARK pair: no link is left, an empty input as one
        # of pairs without inliers is (clean-db warns and writes the copy unchanged)
        watermarks = with_inliers - len(usable)
    # two-view geometries all without inliers: the images were matched and verified and no
    # pair held a match, an empty input (read as none, which clean-db warns of, as resolve
    # does of an empty links file); no two-view geometry at all: a step was never run
    if not n_rows:
        what = "no two-view geometries"
        if raw[0]:
            raise InputError(
                f"database {str(path)!r} has {what}: its {raw[0]} matches of {raw[1]} image "
                f"pairs were never geometrically verified (matched with the verification "
                f"skipped). Verify them first, e.g. pycolmap.verify_matches(DB, PAIRS_TXT), or "
                f"match again with COLMAP's matcher")
        raise InputError(
            f"database {str(path)!r} has {what}: it holds no verified matches. Run COLMAP's "
            f"matcher (e.g. 'colmap exhaustive_matcher') or hloc's geometric verification first")
    parts = []
    fundamental = {}
    for pid, g in usable:
        id1, id2 = divmod(int(pid), MAX_PAIR_ID_IMAGE)  # as stored (checked: both exist)
        a, b = cam_of_id[int(id1)], cam_of_id[int(id2)]
        m = np.asarray(g.inlier_matches, dtype=np.int64).reshape(-1, 2)
        F = _fundamental_px(g)
        if a > b:
            a, b, m = b, a, m[:, ::-1]
            F = None if F is None else F.T
        if F is not None:
            fundamental[(a, b)] = F
        parts.append((np.full(len(m), a), m[:, 0], np.full(len(m), b), m[:, 1],
                      np.full(len(m), int(pid), dtype=np.int64)))
    ci, fi, cj, fj, source = (np.concatenate(col).astype(np.int64) for col in
                              zip(*parts, strict=True)) if parts else \
        (np.zeros(0, dtype=np.int64) for _ in range(5))
    m = np.array([len(k) for k in kps], dtype=np.int64)
    bad = np.flatnonzero((fi >= m[ci]) | (fj >= m[cj]))
    if bad.size:
        k = bad[0]
        cam, feat = (ci[k], fi[k]) if fi[k] >= m[ci[k]] else (cj[k], fj[k])
        raise InputError(
            f"database {str(path)!r}: a two-view geometry of {names[ci[k]]} / {names[cj[k]]} "
            f"names keypoint {feat} of {names[cam]}, which has {m[cam]} stored keypoints; the "
            "database is inconsistent (rebuild it with COLMAP)")
    links = Links(ci, fi, cj, fj)
    # Assumption 2.2 (one-to-one per pair): every inlier of a feature linked twice or more
    # into one other image (a database stores no score to tell which of them is right)
    n = len(names)
    offs = np.concatenate([[0], np.cumsum(m)])
    ga, gb = offs[ci] + fi, offs[cj] + fj
    not_one_to_one = _repeated(ga * n + cj) | _repeated(gb * n + ci)
    return DatabaseContents(path=path, names=names, image_ids=image_ids, keypoints=kps,
                            links=links, not_one_to_one=not_one_to_one,
                            pairs_without_inliers=max(n_rows, len(pair_ids)) - len(usable)
                            - watermarks, watermark_pairs_ignored=watermarks,
                            cameras=[cameras.get(im.camera_id) for im in images],
                            fundamental=fundamental, link_pair_id=source)


#: how far (a fraction of the longer side) a keypoint may lie outside its camera's image
KEYPOINT_MARGIN = 0.05


def _check_keypoints(path: Path, name: str, keypoints, camera) -> None:
    """InputError unless every keypoint of image ``name`` is a finite position in its camera's
    ``W x H`` image (COLMAP's convention, ``[0, W] x [0, H]``), give or take
    :data:`KEYPOINT_MARGIN` of the longer side; a camera of unknown size (0) bounds nothing.

    NaN keypoints were refused later under the pipeline's camera index, not the image's name;
    keypoints at another resolution than their camera (or absurd ones, ``1e30``) were read as
    they were, and ``--fusion``'s mapping never returned on such a database.
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.size == 0:
        return
    xy = kp.reshape(len(kp), -1)[:, :2]
    finite = np.isfinite(xy).all(axis=1)
    if not finite.all():
        k = int(np.flatnonzero(~finite)[0])
        raise InputError(f"database {str(path)!r}: keypoint {k} of image {name!r} is "
                         f"[{xy[k, 0]:g}, {xy[k, 1]:g}], not a position; the database is "
                         "corrupt (rebuild it with COLMAP)")
    w, h = (0, 0) if camera is None else (int(camera.width), int(camera.height))
    if w <= 0 or h <= 0:
        return
    margin = KEYPOINT_MARGIN * max(w, h)
    out = ((xy[:, 0] < -margin) | (xy[:, 0] > w + margin)
           | (xy[:, 1] < -margin) | (xy[:, 1] > h + margin))
    if out.any():
        k = int(np.flatnonzero(out)[0])
        raise InputError(f"database {str(path)!r}: keypoint {k} of image {name!r} at "
                         f"[{xy[k, 0]:g}, {xy[k, 1]:g}] lies outside the {w}x{h} image of its "
                         f"camera ({int(out.sum())} of its {len(xy)} keypoints do); keypoints "
                         "and camera of different resolutions, or a corrupt database: rebuild "
                         "it with COLMAP")


def _fundamental_px(geometry) -> np.ndarray | None:
    """A two-view geometry's ``F`` in OpenCV pixels, or ``None`` if it has none.

    COLMAP's pixel origin is the corner of the top-left pixel (``x_colmap = T x_cv``, ``T``
    the shift by :data:`COLMAP_PIXEL_OFFSET`), so ``F_cv = Tᵀ F T``.
    """
    F = getattr(geometry, "F", None)
    if F is None:
        return None
    F = np.asarray(F, dtype=np.float64)
    if F.shape != (3, 3) or not np.isfinite(F).all() or not np.abs(F).max(initial=0) > 0:
        return None
    T = np.array([[1.0, 0.0, COLMAP_PIXEL_OFFSET], [0.0, 1.0, COLMAP_PIXEL_OFFSET],
                  [0.0, 0.0, 1.0]])
    return T.T @ F @ T


def write_cleaned_database(contents: DatabaseContents, out_path: str | Path,
                           keep: np.ndarray) -> Path:
    """Copy the database read as ``contents`` to ``out_path`` keeping only the ``keep``
    two-view inliers.

    Parameters
    ----------
    contents : DatabaseContents — from :func:`read_database` (its snapshot is copied, so the
        copy holds exactly what was read, even if the input changed since)
    out_path : new database file; must differ from the input
    keep : ndarray, (L,) bool — aligned with ``contents.links``

    Returns
    -------
    out_path : Path, written atomically (copy to a temp file, edit, rename)

    Notes
    -----
    Every two-view-geometry row that holds links is rewritten with exactly the kept ones, in
    its own stored orientation and order (the row is found by its stored ``pair_id``).
    Everything else (cameras, rigs, frames, keypoints, descriptors, the raw ``matches`` table,
    F/E/H of each pair) is copied unchanged; a pair left without inliers keeps its row with an
    empty inlier list, which COLMAP's mapper ignores like any pair below its match minimum.
    """
    import sqlite3

    src, out_path = Path(contents.path), Path(out_path)
    keep = np.asarray(keep, dtype=bool)
    if keep.shape != (len(contents.links),):
        raise InputError(f"keep has shape {keep.shape}, expected ({len(contents.links)},)")
    if out_path.exists() and out_path.resolve() == src.resolve():
        raise InputError(f"--out {str(out_path)!r} is the input database; the input is never "
                         f"modified, choose a new file")
    if contents.snapshot is None or contents.link_pair_id is None:
        raise InputError("write_cleaned_database needs the contents returned by read_database")
    source = contents.link_pair_id
    with _atomic_database(out_path, copy_from=contents.snapshot) as tmp:
        con = sqlite3.connect(tmp)
        try:
            for pid in np.unique(source).tolist():
                sel = source == pid
                rows, data = con.execute("SELECT rows, data FROM two_view_geometries WHERE "
                                         "pair_id = ?", (pid,)).fetchone()
                m = np.frombuffer(data or b"", dtype=np.uint32).reshape(-1, 2)
                if len(m) != int(sel.sum()):
                    raise InputError(f"database {str(src)!r}: pair_id {pid} holds {len(m)} "
                                     f"inliers but {int(sel.sum())} were read")
                kept = np.ascontiguousarray(m[keep[sel]])
                con.execute("UPDATE two_view_geometries SET rows = ?, cols = 2, data = ? "
                            "WHERE pair_id = ?", (len(kept), kept.tobytes(), pid))
            con.commit()
        finally:
            con.close()
    return out_path


def relative_rotations(contents: DatabaseContents) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each verified pair's relative rotation, estimated on its stored inliers.

    ``pycolmap.estimate_relative_pose``: LO-RANSAC of the essential matrix on the pair's
    two-view-geometry inliers with the database's cameras (their focal length, or COLMAP's
    guess of it), at COLMAP's verification threshold (4 px), seeded for repeatable output.
    Not the pose of the stored geometry: decomposing a stored homography (planar pairs) or
    ``F`` picked the wrong one of its solutions on right pairs of the Sceaux photos (on the
    640 px copy, 5 of 55 pairs more than 90° from COLMAP's own reconstruction of them; none
    with the essential matrix).

    Parameters
    ----------
    contents : DatabaseContents — from :func:`read_database` (its snapshot is read again)

    Returns
    -------
    pairs : (P, 2) int64 — camera pairs ``(i, j)``, ``i < j`` (the order of ``contents.names``)
    rotations : (P, 3, 3) — ``R_ij``, camera ``j``'s rotation from camera ``i``'s; NaN where no
        pose was found (no camera, too few inliers)
    inliers : (P,) int64 — the pair's stored inlier count
    """
    if contents.snapshot is None:
        raise InputError("relative_rotations needs the contents returned by read_database")
    cam_of_id = {int(iid): k for k, iid in enumerate(contents.image_ids)}
    with quiet_colmap(), pycolmap.Database.open(contents.snapshot) as db:
        pair_ids, geometries = db.read_two_view_geometries()
    options = pycolmap.RANSACOptions()
    options.max_error = 4.0
    options.random_seed = 0
    rows = []
    for pid, g in zip(pair_ids, geometries, strict=True):
        m = np.asarray(g.inlier_matches, dtype=np.int64).reshape(-1, 2)
        if not len(m):
            continue
        id1, id2 = divmod(int(pid), MAX_PAIR_ID_IMAGE)
        a, b = cam_of_id[int(id1)], cam_of_id[int(id2)]
        R = np.full((3, 3), np.nan)
        cam_a, cam_b = contents.cameras[a], contents.cameras[b]
        if cam_a is not None and cam_b is not None and len(m) >= 5:
            xa = contents.keypoints[a][m[:, 0]].astype(np.float64) + COLMAP_PIXEL_OFFSET
            xb = contents.keypoints[b][m[:, 1]].astype(np.float64) + COLMAP_PIXEL_OFFSET
            try:
                with quiet_colmap():
                    got = pycolmap.estimate_relative_pose(cam_a, xa, cam_b, xb, options)
            except (RuntimeError, ValueError):
                got = None
            if got is not None:
                R = np.asarray(got["cam2_from_cam1"].rotation.matrix(), dtype=np.float64)
        if a > b:
            a, b, R = b, a, R.T
        rows.append((a, b, R, len(m)))
    if not rows:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    rows.sort(key=lambda r: (r[0], r[1]))
    return (np.array([(a, b) for a, b, _, _ in rows], dtype=np.int64),
            np.stack([R for _, _, R, _ in rows]),
            np.array([k for _, _, _, k in rows], dtype=np.int64))
