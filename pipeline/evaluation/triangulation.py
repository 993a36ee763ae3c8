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
           "write_reconstruction", "medoid", "medoids", "reprojection_errors"]


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
            # no observation: no ratio (a 0.0 would read as every observation rejected)
            "inlier_ratio": float(n_inl / n_obs) if n_obs else None,
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


def medoids(points: np.ndarray, groups: list[np.ndarray]) -> np.ndarray:
    """:func:`medoid` of ``points[g]`` for every ``g`` in ``groups``, vectorized.

    Groups with the same number of finite points are solved together (one batched distance
    matrix each), with the same arithmetic as :func:`medoid`, so the results are equal to it
    bit for bit.

    Parameters
    ----------
    points : ndarray, (M, 3) float — nan rows are ignored
    groups : list of (k_g,) int arrays — indices into ``points``

    Returns
    -------
    ndarray, (G, 3) float64 — ``nan`` rows for groups without a finite point

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0., 0, 0], [1, 0, 0], [5, 0, 0], [np.nan, 0, 0]])
    >>> medoids(pts, [np.array([0, 1, 2]), np.array([3])])
    array([[ 1.,  0.,  0.],
           [nan, nan, nan]])
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full((len(groups), 3), np.nan)
    if not groups:
        return out
    sizes = np.fromiter((len(g) for g in groups), dtype=np.int64, count=len(groups))
    members = np.concatenate([np.asarray(g, dtype=np.int64) for g in groups]) \
        if sizes.sum() else np.zeros(0, dtype=np.int64)
    finite = np.isfinite(points).all(axis=1)[members]
    group_of = np.repeat(np.arange(len(groups)), sizes)
    members, group_of = members[finite], group_of[finite]
    k_of = np.bincount(group_of, minlength=len(groups))
    starts = np.cumsum(k_of) - k_of
    for k in np.unique(k_of[k_of > 0]).tolist():
        gs = np.flatnonzero(k_of == k)
        p = points[members[starts[gs][:, None] + np.arange(k)]]          # (G_k, k, 3)
        d = np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1).sum(axis=2)
        out[gs] = p[np.arange(len(gs)), np.argmin(d, axis=1)]
    return out


def triangulate_tracks(views: list[View], features: list[Features], links: Links,
                       options: TriangulationOptions | None = None,
                       gt_points: list[np.ndarray] | None = None,
                       solved_tracks: dict | None = None) -> TrackTriangulation:
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
    solved_tracks : dict, optional
        Tracks already triangulated with these views, features and options, keyed by their
        feature ids; filled with the new ones. Several link sets of one run (before and
        after each stage) share most of their tracks, and a track's triangulation depends on
        its observations only (the RANSAC is seeded), so each is solved once.

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

    cache = {} if solved_tracks is None else solved_tracks
    keys = [feats.tobytes() for feats in tracks]
    new = {key: feats for key, feats in zip(keys, tracks, strict=True) if key not in cache}
    cache.update(zip(new, colmap.triangulate_known_poses(
        views, [(cam_of[feats], all_kp[feats]) for feats in new.values()],
        max_error_px=options.max_error_px, min_tri_angle_deg=options.min_tri_angle_deg,
        seed=options.seed), strict=True))
    solved = [cache[key] for key in keys]

    T = len(tracks)
    xyz = np.full((T, 3), np.nan)
    ok = np.array([res is not None for res in solved], dtype=bool).reshape(T)
    for k in np.flatnonzero(ok):
        xyz[k] = solved[k][0]
    sizes = np.fromiter((len(f) for f in tracks), dtype=np.int64, count=T)
    obs = np.concatenate(tracks) if T else np.zeros(0, dtype=np.int64)
    # every observation of the triangulated tracks at once, then split per track
    X_obs = np.repeat(xyz, sizes, axis=0)
    errors_all = reprojection_errors(views, X_obs[np.repeat(ok, sizes)],
                                     cam_of[obs[np.repeat(ok, sizes)]],
                                     all_kp[obs[np.repeat(ok, sizes)]])
    ok_sizes = sizes[ok]
    ok_errors = np.split(errors_all, np.cumsum(ok_sizes)[:-1]) if len(ok_sizes) else []
    inliers, errors = [], []
    ok_k = iter(range(len(ok_sizes)))
    for k, feats in enumerate(tracks):
        if ok[k]:
            inliers.append(solved[k][1])
            errors.append(ok_errors[next(ok_k)])
        else:
            inliers.append(np.zeros(len(feats), dtype=bool))
            errors.append(np.full(len(feats), np.nan))
    gt_error = np.full(T, np.nan)
    if all_gt is not None and ok.any():
        gt = medoids(all_gt, [tracks[k] for k in np.flatnonzero(ok)])
        gt_error[ok] = [float(np.linalg.norm(X - g)) for X, g in zip(xyz[ok], gt, strict=True)]
    return TrackTriangulation(track_of_feature, tracks, xyz, ok, inliers, errors, gt_error)


def reprojection_errors(views: list[View], X: np.ndarray, cams: np.ndarray,
                        kp: np.ndarray) -> np.ndarray:
    """Reprojection error of each observation, pixels.

    Parameters
    ----------
    views : list of View, (n,) with K, R, t
    X : ndarray, (N, 3) — world point of each observation
    cams : ndarray, (N,) int — camera of each observation
    kp : ndarray, (N, 2) — its keypoint (OpenCV pixel convention)

    Returns
    -------
    ndarray, (N,) float64 — ``|π(K (R X + t)) - kp|``; ``inf`` where the point is not in
    front of the camera
    """
    X = np.asarray(X, dtype=np.float64).reshape(-1, 3)
    cams = np.asarray(cams, dtype=np.int64).reshape(-1)
    if not len(cams):
        return np.zeros(0)
    K = np.stack([np.asarray(v.K, dtype=np.float64) for v in views])
    R = np.stack([np.asarray(v.R, dtype=np.float64) for v in views])
    t = np.stack([np.asarray(v.t, dtype=np.float64).reshape(3) for v in views])
    # stacked (3,3) @ (3,1) products: the arithmetic of K @ (R @ X + t) per observation
    y = (R[cams] @ X[:, :, None])[:, :, 0] + t[cams]
    x = (K[cams] @ y[:, :, None])[:, :, 0]
    out = np.full(len(cams), np.inf)
    front = x[:, 2] > 0
    out[front] = np.linalg.norm(x[front, :2] / x[front, 2:3] - np.asarray(kp, np.float64)
                                .reshape(-1, 2)[front], axis=1)
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
    all_kp = np.concatenate([np.asarray(f.keypoints, dtype=np.float64).reshape(-1, 2)
                             for f in features] + [np.zeros((0, 2))])
    n = len(views)
    points = []
    for k in np.flatnonzero(tri.ok):
        keep = tri.track_features[k][tri.inliers[k]]
        cams = cam_of[keep]
        seen = np.bincount(cams, minlength=n)
        if int((seen > 0).sum()) < 2 or (seen > 1).any():
            # a COLMAP track holds one observation per image at most (a conflictive track)
            continue
        elements = list(zip(cams.tolist(), (keep - offsets[cams]).tolist(), strict=True))
        points.append((tri.xyz[k], elements, int(keep[0])))
    colors = _colors(views, cam_of, all_kp, np.array([p[2] for p in points], dtype=np.int64))
    points = [(xyz, elements, color) for (xyz, elements, _), color
              in zip(points, colors, strict=True)]
    return colmap.write_points_model(path, views, features, points)


def _colors(views: list[View], cam_of: np.ndarray, all_kp: np.ndarray,
            feature_ids: np.ndarray) -> np.ndarray:
    """RGB of each feature's image at its keypoint (nearest pixel, clipped to the image),
    ``(F,)`` ids in, ``(F, 3)`` uint8 out; a gray image gives gray triples."""
    out = np.zeros((len(feature_ids), 3), dtype=np.uint8)
    cams = cam_of[feature_ids]
    for c in np.unique(cams).tolist():
        sel = np.flatnonzero(cams == c)
        img = views[c].image
        h, w = img.shape[:2]
        xy = all_kp[feature_ids[sel]]
        u = np.clip(np.rint(xy[:, 0]).astype(np.int64), 0, w - 1)   # round half to even, as
        v = np.clip(np.rint(xy[:, 1]).astype(np.int64), 0, h - 1)   # Python's round()
        px = img[v, u]
        out[sel] = px.reshape(len(sel), -1)[:, :3] if px.ndim > 1 else px[:, None]
    return out
