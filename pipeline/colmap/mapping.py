"""COLMAP incremental mapping and what the pipeline reads from a reconstruction.

- :func:`incremental_mapping` — ``pycolmap.incremental_mapping`` and its figures (registered
  images, points, mean track length, mean reprojection error).
- :func:`registered_poses`, :func:`similarity_between` — poses and gauge of a reconstruction.
- :func:`write_model`, :func:`read_model` — a reconstruction as a COLMAP model folder.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycolmap

from pipeline.colmap.base import COLMAP_PIXEL_OFFSET, quiet_colmap
from pipeline.colmap.database import check_database_file
from pipeline.errors import InputError

__all__ = ["MappingSummary", "incremental_mapping", "write_model", "read_model",
           "model_images", "model_points", "model_tracks", "registered_poses",
           "undistorted_keypoints",
           "similarity_between"]


@dataclass
class MappingSummary:
    """Figures of an incremental reconstruction (the largest model when there are several).

    Attributes
    ----------
    images : int — images in the database
    models : int — reconstructions COLMAP produced
    registered_images : int — images registered in the largest model
    registered_names : list[str]
    points : int — 3D points of the largest model
    observations : int — 2D observations of those points
    mean_track_length : float — observations per point
    mean_reprojection_error : float — pixels
    reconstruction : pycolmap.Reconstruction or None
    """

    images: int
    models: int
    registered_images: int
    registered_names: list[str]
    points: int
    observations: int
    mean_track_length: float
    mean_reprojection_error: float
    reconstruction: object = None

    def summary(self) -> dict:
        """The figures as a JSON-ready dict (without the reconstruction)."""
        return {"images": self.images, "models": self.models,
                "registered_images": self.registered_images,
                "registered_names": list(self.registered_names), "points": self.points,
                "observations": self.observations,
                "mean_track_length": round(float(self.mean_track_length), 4),
                "mean_reprojection_error": round(float(self.mean_reprojection_error), 4)}


def incremental_mapping(database_path: str | Path, *, image_dir: str | Path = "",
                        output_dir: str | Path | None = None, num_threads: int = -1,
                        seed: int = 0, fixed_intrinsics=()) -> MappingSummary:
    """``pycolmap.incremental_mapping`` on a database; figures of the largest model.

    Parameters
    ----------
    database_path : database with two-view geometries (e.g. from :func:`write_database`)
    image_dir : folder of the images, only to colour points; ``""`` skips colours (the
        pipeline maps downscaled images whose files do not exist at that size)
    output_dir : where COLMAP writes its models; a temporary folder when None
    num_threads : COLMAP threads (-1: all cores)
    seed : COLMAP's random seed, for repeatable figures
    fixed_intrinsics : iterable of image names whose calibration the bundle adjustments keep
        (with few views COLMAP otherwise lets the focal length drift far from a known
        calibration at no cost in reprojection error): when it names every image, no focal
        length is refined and the distortion terms still are; otherwise those cameras are
        held constant

    Returns
    -------
    MappingSummary — zeros when no model could be initialised
    """
    database_path = Path(database_path)
    check_database_file(database_path)
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = num_threads
    options.random_seed = seed
    options.extract_colors = bool(image_dir)
    with tempfile.TemporaryDirectory(prefix="colmap-map-") as tmp:
        out = Path(output_dir) if output_dir is not None else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        with quiet_colmap():
            with pycolmap.Database.open(database_path) as db:
                n_images = db.num_images()
                fixed = set(fixed_intrinsics)
                images = db.read_all_images()
                if images and all(im.name in fixed for im in images):
                    # every camera calibrated: focal lengths kept, a radial term refined
                    # (a pinhole camera has none to refine)
                    options.ba_refine_focal_length = False
                else:
                    options.constant_cameras = {im.camera_id for im in images
                                                if im.name in fixed}
            # COLMAP insists on an existing image folder even when it reads no pixels;
            # a progress bar counts the images as the mapper registers them
            from pipeline.progress import progress

            with progress(None, total=n_images, desc="mapping (images registered)") as bar:
                models = pycolmap.incremental_mapping(
                    database_path, str(image_dir or tmp), out, options,
                    initial_image_pair_callback=lambda: bar.update(2),
                    next_image_callback=lambda: bar.update(1))
    if not models:
        return MappingSummary(n_images, 0, 0, [], 0, 0, 0.0, 0.0, None)
    rec = max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D()))
    rec.update_point_3d_errors()
    names = sorted(rec.images[i].name for i in rec.reg_image_ids())
    return MappingSummary(
        images=n_images, models=len(models), registered_images=rec.num_reg_images(),
        registered_names=names, points=rec.num_points3D(),
        observations=int(rec.compute_num_observations()),
        mean_track_length=float(rec.compute_mean_track_length()) if rec.num_points3D() else 0.0,
        mean_reprojection_error=float(rec.compute_mean_reprojection_error()),
        reconstruction=rec)


def write_model(path: str | Path, reconstruction=None) -> Path:
    """Write ``reconstruction`` (an empty one when ``None``) as a COLMAP model folder that
    loads back with :func:`read_model`; the folder is created."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    (reconstruction if reconstruction is not None else pycolmap.Reconstruction()).write(path)
    return path


def rescale_to_files(rec, sizes: dict[str, tuple[int, int]]) -> None:
    """Scale a reconstruction made on downscaled images back to the image files, in place.

    Parameters
    ----------
    rec : pycolmap.Reconstruction — cameras and 2D points at the size that was mapped
    sizes : ``{image name: (width, height)}`` of the files the images were loaded from

    Notes
    -----
    In COLMAP's pixel convention (origin at the top-left *corner*) resizing an image by
    ``(sx, sy)`` multiplies every pixel coordinate by ``(sx, sy)``: ``Camera.rescale`` scales
    focal lengths and principal point, each 2D point is scaled likewise. A camera shared by
    several images is rescaled once. Poses and 3D points do not change.
    """
    factor: dict[int, tuple[float, float]] = {}
    for image in rec.images.values():
        if image.name not in sizes:
            continue
        W, H = (int(v) for v in sizes[image.name])
        if image.camera_id not in factor:
            cam = rec.cameras[image.camera_id]
            factor[image.camera_id] = (W / cam.width, H / cam.height)
            if (W, H) != (cam.width, cam.height):
                cam.rescale(W, H)
        sx, sy = factor[image.camera_id]
        if (sx, sy) == (1.0, 1.0):
            continue
        for p in image.points2D:
            xy = p.xy
            p.xy = np.array([xy[0] * sx, xy[1] * sy])


def write_model_for_files(path: str | Path, reconstruction, sizes: dict[str, tuple[int, int]],
                          image_dir: str | Path) -> Path:
    """Write ``reconstruction`` as a model folder at the resolution of its image files.

    A copy is scaled (:func:`rescale_to_files`) and its points take their colours from the
    files in ``image_dir``; ``reconstruction`` itself is left at the size it was mapped at.
    """
    path = write_model(path, reconstruction)
    if reconstruction is None:
        return path
    full = pycolmap.Reconstruction(str(path))
    rescale_to_files(full, sizes)
    with quiet_colmap():
        full.extract_colors_for_all_images(str(image_dir))
    full.write(path)
    return path


def read_model(path: str | Path):
    """The ``pycolmap.Reconstruction`` of a COLMAP model folder (e.g. a run's ``sparse/``)."""
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"COLMAP model {str(path)!r}: no such folder")
    return pycolmap.Reconstruction(str(path))


def model_images(rec) -> dict[str, dict]:
    """Every image of a reconstruction by name: ``image_id``, ``size`` ``(w, h)``, ``K``
    (3, 3) and ``keypoints`` (N, 2) in the OpenCV pixel convention, and ``R`` (3, 3), ``t``
    (3,) ``cam_from_world`` where the image is registered (else ``None``)."""
    out = {}
    if rec is None:
        return out
    registered = set(rec.reg_image_ids())
    for image_id, image in rec.images.items():
        cam = rec.cameras[image.camera_id]
        K = np.array(cam.calibration_matrix(), dtype=np.float64)
        K[:2, 2] -= COLMAP_PIXEL_OFFSET
        kp = np.array([p.xy for p in image.points2D], dtype=np.float64).reshape(-1, 2)
        R = t = None
        if image_id in registered:
            pose = image.cam_from_world()
            R = np.asarray(pose.rotation.matrix(), dtype=np.float64)
            t = np.asarray(pose.translation, dtype=np.float64).reshape(3)
        out[image.name] = {"image_id": int(image_id), "size": (int(cam.width), int(cam.height)),
                           "K": K, "keypoints": kp - COLMAP_PIXEL_OFFSET, "R": R, "t": t}
    return out


def model_points(rec) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray]:
    """The 3D points of a reconstruction, in its own order.

    Returns
    -------
    xyz : (P, 3) float64
    point_ids : (P,) int64
    first_image : list of P str — name of the image of each point's first observation
    first_keypoint : (P,) int64 — index of that observation's keypoint in its image
    """
    if rec is None or rec.num_points3D() == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64), [], np.zeros(0, dtype=np.int64)
    xyz, ids, names, kp = [], [], [], []
    for point_id, p in rec.points3D.items():
        el = p.track.elements[0]
        xyz.append(p.xyz)
        ids.append(point_id)
        names.append(rec.images[el.image_id].name)
        kp.append(el.point2D_idx)
    return (np.asarray(xyz, dtype=np.float64).reshape(-1, 3), np.asarray(ids, dtype=np.int64),
            names, np.asarray(kp, dtype=np.int64))


def model_tracks(rec) -> list[list[tuple[str, float, float]]]:
    """Every 3D point's track: its observations ``(image name, x, y)`` in COLMAP's pixel
    convention, in the reconstruction's point order."""
    if rec is None:
        return []
    names = {i: im.name for i, im in rec.images.items()}
    out = []
    for p in rec.points3D.values():
        track = []
        for el in p.track.elements:
            xy = rec.images[el.image_id].points2D[el.point2D_idx].xy
            track.append((names[el.image_id], float(xy[0]), float(xy[1])))
        out.append(track)
    return out


def undistorted_keypoints(rec, name: str, xy: np.ndarray) -> np.ndarray:
    """Keypoints ``(m, 2)`` (OpenCV convention) of image ``name`` with its camera's lens
    distortion removed: where a pinhole with the camera's own ``K``
    (:func:`registered_poses`) would have seen them. Unchanged for a camera without distortion
    or an image not in ``rec``."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    image = next((im for im in rec.images.values() if im.name == name), None) \
        if rec is not None else None
    if image is None or len(xy) == 0:
        return xy.copy()
    cam = rec.cameras[image.camera_id]
    rays = np.asarray(cam.cam_from_img(xy + COLMAP_PIXEL_OFFSET), dtype=np.float64)
    K = np.asarray(cam.calibration_matrix(), dtype=np.float64)
    out = rays @ K[:2, :2].T + K[:2, 2]
    bad = ~np.isfinite(out).all(axis=1)
    out[bad] = xy[bad] + COLMAP_PIXEL_OFFSET
    return out - COLMAP_PIXEL_OFFSET


def registered_poses(rec) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``{image name: (R (3, 3), t (3,), K (3, 3))}`` of the registered images of ``rec``.

    ``R, t`` is ``cam_from_world``; ``K`` is the (possibly refined) camera in the OpenCV pixel
    convention.
    """
    out = {}
    if rec is None:
        return out
    for image_id in rec.reg_image_ids():
        image = rec.images[image_id]
        pose = image.cam_from_world()
        K = np.array(rec.cameras[image.camera_id].calibration_matrix(), dtype=np.float64)
        K[:2, 2] -= COLMAP_PIXEL_OFFSET
        out[image.name] = (np.asarray(pose.rotation.matrix(), dtype=np.float64),
                           np.asarray(pose.translation, dtype=np.float64).reshape(3), K)
    return out


def similarity_between(src, tgt) -> np.ndarray | None:
    """``tgt_from_src`` similarity ``(3, 4)`` (``x_tgt = M[:, :3] @ x_src + M[:, 3]``) from the
    projection centres of the images registered in both reconstructions (by name), or None
    with fewer than three such images. Two reconstructions of one scene have different gauges;
    this puts points of one into the frame of the other."""
    a, b = registered_poses(src), registered_poses(tgt)
    common = sorted(set(a) & set(b))
    if len(common) < 3:
        return None
    src_c = np.stack([-a[k][0].T @ a[k][1] for k in common])  # projection centres
    tgt_c = np.stack([-b[k][0].T @ b[k][1] for k in common])
    sim = pycolmap.estimate_sim3d(src_c, tgt_c)
    return None if sim is None else np.asarray(sim.matrix(), dtype=np.float64)
