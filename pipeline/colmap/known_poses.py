"""pycolmap with known camera poses: robust triangulation of tracks and writing them as a model.

Used by :mod:`pipeline.evaluation.triangulation` (the check of the cleaned tracks of a rendered
formation). Cameras are ``PINHOLE`` with ids ``camera index + 1``; image ids likewise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pycolmap

from pipeline.colmap.base import COLMAP_PIXEL_OFFSET, quiet_colmap, rigid, write_reconstruction
from pipeline.types import Features, View

__all__ = ["triangulate_known_poses", "build_reconstruction", "write_points_model"]


def _camera(view: View, camera_id: int) -> pycolmap.Camera:
    w, h = view.size
    K = view.K
    return pycolmap.Camera(model="PINHOLE", width=w, height=h, camera_id=camera_id,
                           params=[K[0, 0], K[1, 1], K[0, 2] + COLMAP_PIXEL_OFFSET,
                                   K[1, 2] + COLMAP_PIXEL_OFFSET])


def _pose(view: View) -> pycolmap.Rigid3d:
    if view.R is None or view.t is None:
        raise ValueError(f"view {view.name!r} has no pose; known-pose triangulation needs R and t")
    return rigid(view.R, view.t)


def triangulate_known_poses(views: list[View], observations: list[tuple[np.ndarray, np.ndarray]],
                            *, max_error_px: float, min_tri_angle_deg: float,
                            seed: int) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """Robust triangulation (``pycolmap.estimate_triangulation``, LO-RANSAC, reprojection
    residual in pixels) of each point seen by known cameras.

    Parameters
    ----------
    views : list of View, (n,) with K, R, t
    observations : list of ``(cams (k,) int, keypoints (k, 2))`` — per point, the cameras that
        see it and its keypoints in the OpenCV pixel convention
    max_error_px : inlier threshold of the reprojection residual
    min_tri_angle_deg : minimum triangulation angle (pycolmap's default 0 lets degenerate
        tracks pass)
    seed : RANSAC seed

    Returns
    -------
    list, one per point: ``(xyz (3,), inliers (k,) bool)``, or ``None`` where it failed
    """
    cameras = [_camera(v, k + 1) for k, v in enumerate(views)]
    poses = [_pose(v) for v in views]
    opts = pycolmap.EstimateTriangulationOptions()
    opts.min_tri_angle = float(np.deg2rad(min_tri_angle_deg))
    opts.residual_type = pycolmap.TriangulationResidualType.REPROJECTION_ERROR
    opts.ransac.max_error = float(max_error_px)
    opts.ransac.random_seed = int(seed)
    out = []
    with quiet_colmap():
        for cams, kp in observations:
            res = pycolmap.estimate_triangulation(kp + COLMAP_PIXEL_OFFSET,
                                                  [poses[c] for c in cams],
                                                  [cameras[c] for c in cams], opts)
            if res is None:
                out.append(None)
                continue
            out.append((np.asarray(res["xyz"], dtype=np.float64).reshape(3),
                        np.asarray(res["inliers"], dtype=bool).reshape(-1)))
    return out


def build_reconstruction(views: list[View], features: list[Features]) -> pycolmap.Reconstruction:
    """A ``pycolmap.Reconstruction`` with one PINHOLE camera, rig and frame per view and its
    keypoints (shifted to COLMAP's pixel convention). Image ids are ``camera index + 1``."""
    rec = pycolmap.Reconstruction()
    for k, (v, f) in enumerate(zip(views, features, strict=True)):
        cam = _camera(v, k + 1)
        rec.add_camera_with_trivial_rig(cam)
        kp = f.keypoints.astype(np.float64) + COLMAP_PIXEL_OFFSET if len(f) else np.zeros((0, 2))
        image = pycolmap.Image(name=v.name, keypoints=kp, camera_id=k + 1, image_id=k + 1)
        rec.add_image_with_trivial_frame(image, _pose(v))
    return rec


def write_points_model(path: str | Path, views: list[View], features: list[Features],
                       points: list[tuple[np.ndarray, list[tuple[int, int]], np.ndarray]]
                       ) -> pycolmap.Reconstruction:
    """Write views, keypoints and 3D points as a COLMAP model folder at ``path``.

    Parameters
    ----------
    points : list of ``(xyz (3,), [(camera index, keypoint index), …], rgb (3,) uint8)``; a
        track holds one observation per image at most

    Returns
    -------
    pycolmap.Reconstruction — what was written (loads back with ``pycolmap.Reconstruction(path)``)
    """
    rec = build_reconstruction(views, features)
    for xyz, elements, color in points:
        track = pycolmap.Track()
        for cam, feat in elements:
            track.add_element(int(cam) + 1, int(feat))
        rec.add_point3D(xyz, track, color)
    with quiet_colmap():
        rec.update_point_3d_errors()
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        write_reconstruction(rec, path)
    return rec
