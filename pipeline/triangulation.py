"""pycolmap check of the cleaned tracks with known camera poses.

Every track (association set: connected component of the links with >= 2 features) is
triangulated robustly with ``pycolmap.estimate_triangulation`` (LO-RANSAC over the track's
observations, reprojection residual in pixels, a minimum triangulation angle). The figures
tell how geometrically sound an association is: a clean track triangulates with all its
observations as inliers; a track that chains two different surface points loses observations
or fails.

The pycolmap calls themselves go through the adapter :mod:`pipeline.colmap`
(:func:`~pipeline.colmap.triangulate_known_poses`, :func:`~pipeline.colmap.write_points_model`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline import colmap
from pipeline.association import association_sets
from pipeline.types import Features, Links, View

__all__ = ["TriangulationOptions", "TrackTriangulation", "triangulate_tracks",
           "write_reconstruction", "medoid"]


@dataclass
class TriangulationOptions:
    """Robust triangulation settings.

    max_error_px : inlier threshold of the reprojection residual, pixels
    min_tri_angle_deg : minimum triangulation angle; pycolmap's default 0 lets degenerate
        (parallel-ray) tracks pass, so it is set
    seed : RANSAC seed, for repeatable runs
    """

    max_error_px: float = 4.0
    min_tri_angle_deg: float = 1.0
    seed: int = 0


@dataclass
class TrackTriangulation:
    """Result of triangulating every track of one association.

    Attributes
    ----------
    track_of_feature : (m,) int — track id of every feature (global index), -1 if in none
    track_features : list of (k,) int arrays — global feature ids of each track
    xyz : (T, 3) — triangulated point per track (nan where it failed)
    ok : (T,) bool — triangulation succeeded
    inliers : list of (k,) bool — per observation of each track
    reproj_error_px : list of (k,) float — per observation
    gt_error : (T,) — distance to the ground-truth point (nan without ground truth)
    """

    track_of_feature: np.ndarray
    track_features: list
    xyz: np.ndarray
    ok: np.ndarray
    inliers: list
    reproj_error_px: list
    gt_error: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def summary(self) -> dict:
        """The figures of the report: tracks, triangulated, errors, inlier ratio, rejections."""
        T = len(self.track_features)
        ok = self.ok
        inl = [m for m, good in zip(self.inliers, ok, strict=True) if good]
        errs = [e[m] for e, m, good in zip(self.reproj_error_px, self.inliers, ok, strict=True) if good]
        all_err = np.concatenate(errs) if errs else np.zeros(0)
        n_obs = int(sum(len(f) for f in self.track_features))
        n_inl = int(sum(int(m.sum()) for m in inl))
        gt = self.gt_error[ok] if self.gt_error.size else np.zeros(0)
        gt = gt[np.isfinite(gt)]
        return {
            "tracks": T,
            "triangulated_tracks": int(ok.sum()),
            "observations": n_obs,
            "inlier_observations": n_inl,
            "inlier_ratio": float(n_inl / n_obs) if n_obs else 0.0,
            "mean_reprojection_error_px": float(all_err.mean()) if all_err.size else None,
            "median_reprojection_error_px": float(np.median(all_err)) if all_err.size else None,
            "median_3d_error": float(np.median(gt)) if gt.size else None,
            "tracks_with_rejected_observation": int(sum(int((~m).any()) for m in inl)),
        }


def medoid(points: np.ndarray) -> np.ndarray:
    """Point of ``points`` (k,3) with least summed distance to the others (nan rows ignored)."""
    p = points[np.isfinite(points).all(axis=1)]
    if not len(p):
        return np.full(3, np.nan)
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1).sum(axis=1)
    return p[int(np.argmin(d))]


def triangulate_tracks(views: list[View], features: list[Features], links: Links,
                       options: TriangulationOptions | None = None,
                       gt_points: list[np.ndarray] | None = None) -> TrackTriangulation:
    """Triangulate every track of ``links`` robustly with the known poses of ``views``.

    Parameters
    ----------
    views : list of View, (n,) with K, R, t
    features : list of Features, (n,)
    links : Links
    options : TriangulationOptions
    gt_points : optional list of (m_i, 3) arrays, ground-truth world point of every keypoint
        (nan where unknown). A track's ground-truth point is the medoid of its observations'
        points, which a minority of wrong observations cannot move; its 3D error is the
        distance from the triangulated point to it.

    Returns
    -------
    TrackTriangulation
    """
    options = options or TriangulationOptions()
    n = len(views)
    m_per = np.array([len(f) for f in features], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(m_per)])
    cam_of = np.repeat(np.arange(n), m_per)
    all_kp = (np.concatenate([f.keypoints for f in features]).astype(np.float64)
              if offsets[-1] else np.zeros((0, 2)))
    all_gt = np.concatenate(gt_points).astype(np.float64) if gt_points is not None and offsets[-1] else None
    track_of_feature, tracks = association_sets(m_per, links)

    solved = colmap.triangulate_known_poses(
        views, [(cam_of[feats], all_kp[feats]) for feats in tracks],
        max_error_px=options.max_error_px, min_tri_angle_deg=options.min_tri_angle_deg,
        seed=options.seed)

    T = len(tracks)
    xyz = np.full((T, 3), np.nan)
    ok = np.zeros(T, dtype=bool)
    inliers, errors = [], []
    gt_error = np.full(T, np.nan)
    for k, (feats, res) in enumerate(zip(tracks, solved, strict=True)):
        if res is None:
            inliers.append(np.zeros(len(feats), dtype=bool))
            errors.append(np.full(len(feats), np.nan))
            continue
        X, inl = res
        xyz[k] = X
        ok[k] = True
        inliers.append(inl)
        errors.append(_reprojection_errors(X, views, cam_of[feats], all_kp[feats]))
        if all_gt is not None:
            gt_error[k] = float(np.linalg.norm(X - medoid(all_gt[feats])))
    return TrackTriangulation(track_of_feature, tracks, xyz, ok, inliers, errors, gt_error)


def _reprojection_errors(X: np.ndarray, views: list[View], cams: np.ndarray,
                         kp: np.ndarray) -> np.ndarray:
    out = np.empty(len(cams))
    for a, c in enumerate(cams):
        v = views[c]
        x = v.K @ (v.R @ X + v.t)
        out[a] = np.inf if x[2] <= 0 else float(np.linalg.norm(x[:2] / x[2] - kp[a]))
    return out


def write_reconstruction(path: str | Path, views: list[View], features: list[Features],
                         tri: TrackTriangulation):
    """Write the triangulated tracks (inlier observations only) as a COLMAP model to ``path``.

    The folder loads back with ``pycolmap.Reconstruction(path)`` and opens in COLMAP; returns
    the ``pycolmap.Reconstruction`` written (:func:`pipeline.colmap.write_points_model`).
    """
    m_per = np.array([len(f) for f in features], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(m_per)])
    cam_of = np.repeat(np.arange(len(views)), m_per)
    points = []
    for k, feats in enumerate(tri.track_features):
        if not tri.ok[k]:
            continue
        keep = feats[tri.inliers[k]]
        cams = cam_of[keep]
        if len(np.unique(cams)) < 2 or len(np.unique(cams)) < len(cams):
            # a COLMAP track holds one observation per image at most (a conflictive track)
            continue
        elements = [(int(c), int(g - offsets[c])) for g, c in zip(keep, cams, strict=True)]
        color = _color(views, cams[0], features[cams[0]].keypoints[keep[0] - offsets[cams[0]]])
        points.append((tri.xyz[k], elements, color))
    return colmap.write_points_model(path, views, features, points)


def _color(views: list[View], cam: int, xy: np.ndarray) -> np.ndarray:
    img = views[cam].image
    h, w = img.shape[:2]
    u = int(np.clip(round(float(xy[0])), 0, w - 1))
    v = int(np.clip(round(float(xy[1])), 0, h - 1))
    px = img[v, u]
    return np.asarray(np.broadcast_to(px, (3,)), dtype=np.uint8)
