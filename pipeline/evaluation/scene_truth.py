"""A reconstruction judged against the exact truth of a rendered photo folder.

The truth (``truth.npz`` beside the images, written by :mod:`data_synth.symmetric`): per
image its name, ``K`` (OpenCV pixel convention), ``cam_from_world`` ``R, t`` and the depth of
every pixel (``inf`` where no surface was hit). From it:

- :func:`pose_errors` — the reconstruction's camera centres aligned to the true ones by a
  similarity (Umeyama's least squares, "Least-squares estimation of transformation parameters
  between two point patterns", PAMI 1991, on the images registered in both), then per image the
  rotation error (degrees, the angle of ``R_est R_simᵀ R_trueᵀ``) and the position error (in
  the truth's metres). A reconstruction is only known up to a similarity; this is its gauge.
- :func:`wrong_tracks` — every 3D point's track with the true 3D point of each observation (the
  depth at its pixel, back-projected with the true pose); a track is *wrong* when two of its
  observations' true points lie farther apart than ``tol_m``: it joins different points of
  the scene. Observations on a depth edge (the 3x3 depths around the pixel differ by more than
  5 %) are not judged.

Interpretation: the judge never uses the reconstruction's own 3D points, only which
observations it put together and where it put the cameras, so a mirrored or folded model
(the failure repeated structure causes) shows as large pose errors and wrong tracks.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.colmap.base import COLMAP_PIXEL_OFFSET
from pipeline.errors import InputError

__all__ = ["SceneTruth", "read_truth", "umeyama", "pose_errors", "wrong_tracks", "wrong_links",
           "TRUTH_FILE", "WRONG_TRACK_TOL_M"]

#: the truth file of a rendered photo folder
TRUTH_FILE = "truth.npz"
#: two observations of one track more than this far apart (metres) make it a wrong track
WRONG_TRACK_TOL_M = 0.1


@dataclass
class SceneTruth:
    """Per image name: ``K`` (3, 3), ``R`` (3, 3), ``t`` (3,), ``depth`` (H, W) float32."""

    names: list[str]
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    depth: np.ndarray

    def index(self) -> dict[str, int]:
        return {n: k for k, n in enumerate(self.names)}

    def centres(self) -> np.ndarray:
        """True projection centres ``(n, 3)``, ``-Rᵀ t``."""
        return -np.einsum("nji,nj->ni", self.R, self.t)


def read_truth(folder: str | Path) -> SceneTruth:
    """The ``truth.npz`` of a rendered photo folder; InputError when it is missing or bad."""
    path = Path(folder) / TRUTH_FILE
    if not path.is_file():
        raise InputError(f"{path}: no truth file (a rendered folder of data_synth.symmetric "
                         f"has one)")
    with np.load(path, allow_pickle=False) as z:
        try:
            names = [str(n) for n in z["names"]]
            K, R, t, depth = (np.asarray(z[k]) for k in ("K", "R", "t", "depth"))
        except KeyError as exc:
            raise InputError(f"{path}: missing array {exc}") from None
    n = len(names)
    if K.shape != (n, 3, 3) or R.shape != (n, 3, 3) or t.shape != (n, 3) or depth.ndim != 3 \
            or len(depth) != n:
        raise InputError(f"{path}: arrays do not describe {n} images (K {K.shape}, R {R.shape}, "
                         f"t {t.shape}, depth {depth.shape})")
    return SceneTruth(names, K.astype(np.float64), R.astype(np.float64), t.astype(np.float64),
                      depth.astype(np.float32))


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``dst ≈ s R src + c`` by least squares (Umeyama 1991, eqs. 40-42).

    Returns ``(s, R (3, 3), c (3,))``; needs three or more non-collinear points.
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    cov = b.T @ a / len(src)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    var = (a * a).sum() / len(src)
    s = float(np.trace(np.diag(D) @ S) / var) if var > 0 else 1.0
    return s, R, mu_d - s * R @ mu_s


def pose_errors(poses: dict[str, tuple[np.ndarray, np.ndarray]], truth: SceneTruth) -> dict:
    """Rotation and position errors of registered cameras against the truth.

    Parameters
    ----------
    poses : ``{image name: (R (3, 3), t (3,))}`` ``cam_from_world`` of the registered images
    truth : SceneTruth

    Returns
    -------
    dict — ``registered``, ``rotation_deg`` and ``position_m`` (each ``median``, ``mean``,
    ``max``) over the images known to both; ``None`` figures with fewer than three such images
    """
    idx = truth.index()
    common = sorted(n for n in poses if n in idx)
    out = {"registered": len(common), "rotation_deg": None, "position_m": None}
    if len(common) < 3:
        return out
    est_c = np.stack([-poses[n][0].T @ poses[n][1] for n in common])
    true_c = truth.centres()[[idx[n] for n in common]]
    s, Rs, c = umeyama(est_c, true_c)
    rot, pos = [], []
    for n, ce in zip(common, est_c, strict=True):
        # world_true = s Rs world_est + c: the camera's rotation in the true frame is R Rsᵀ
        R_al = poses[n][0] @ Rs.T
        dR = R_al @ truth.R[idx[n]].T
        rot.append(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1.0, 1.0))))
        pos.append(np.linalg.norm(s * Rs @ ce + c - truth.centres()[idx[n]]))

    def stats(v):
        v = np.asarray(v)
        return {"median": round(float(np.median(v)), 4), "mean": round(float(v.mean()), 4),
                "max": round(float(v.max()), 4)}

    out.update(rotation_deg=stats(rot), position_m=stats(pos))
    return out


def _true_points(truth: SceneTruth, k: int, xy: np.ndarray):
    """True 3D points ``(m, 3)`` of OpenCV pixels ``xy`` of image ``k`` and which are judged."""
    depth = truth.depth[k]
    H, W = depth.shape
    u = np.clip(np.rint(xy[:, 0]).astype(np.int64), 1, W - 2)
    v = np.clip(np.rint(xy[:, 1]).astype(np.int64), 1, H - 2)
    around = np.stack([depth[v + dv, u + du] for dv in (-1, 0, 1) for du in (-1, 0, 1)])
    z = depth[v, u].astype(np.float64)
    ok = np.isfinite(around).all(0) & (around.max(0) <= 1.05 * around.min(0))
    rays = np.linalg.solve(truth.K[k], np.c_[xy, np.ones(len(xy))].T).T
    X_cam = rays * np.where(ok, z, 0.0)[:, None]
    X = (X_cam - truth.t[k]) @ truth.R[k]  # Rᵀ (X_cam - t)
    return X, ok


def wrong_tracks(tracks: list[list[tuple[str, float, float]]], truth: SceneTruth,
                 tol_m: float = WRONG_TRACK_TOL_M) -> dict:
    """How many tracks join different true points.

    Parameters
    ----------
    tracks : per 3D point, its observations ``(image name, x, y)`` in COLMAP's pixel
        convention at the size of the truth's images (:func:`pipeline.colmap.model_tracks`)
    truth : SceneTruth
    tol_m : see :data:`WRONG_TRACK_TOL_M`

    Returns
    -------
    dict — ``points``, ``judged`` (tracks with two or more judged observations), ``wrong``,
    ``wrong_fraction`` (of the judged), ``tol_m``
    """
    idx = truth.index()
    obs_img, obs_xy, obs_track = [], [], []
    for p, track in enumerate(tracks):
        for name, x, y in track:
            if name in idx:
                obs_img.append(idx[name])
                obs_xy.append((x - COLMAP_PIXEL_OFFSET, y - COLMAP_PIXEL_OFFSET))
                obs_track.append(p)
    obs_img = np.asarray(obs_img, dtype=np.int64)
    obs_xy = np.asarray(obs_xy, dtype=np.float64).reshape(-1, 2)
    obs_track = np.asarray(obs_track, dtype=np.int64)
    X = np.zeros((len(obs_img), 3))
    ok = np.zeros(len(obs_img), dtype=bool)
    for k in np.unique(obs_img):
        sel = obs_img == k
        X[sel], ok[sel] = _true_points(truth, int(k), obs_xy[sel])
    judged = wrong = 0
    order = np.argsort(obs_track[ok], kind="stable")
    Xo, to = X[ok][order], obs_track[ok][order]
    starts = np.flatnonzero(np.r_[True, to[1:] != to[:-1]]) if len(to) else np.zeros(0, int)
    ends = np.r_[starts[1:], len(to)] if len(starts) else np.zeros(0, int)
    for a, b in zip(starts, ends, strict=True):
        if b - a < 2:
            continue
        judged += 1
        P = Xo[a:b]
        spread = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=2).max()
        wrong += int(spread > tol_m)
    return {"points": len(tracks), "judged": judged, "wrong": wrong,
            "wrong_fraction": round(wrong / judged, 4) if judged else 0.0, "tol_m": tol_m}


def wrong_links(names: list[str], keypoints: list[np.ndarray], links, truth: SceneTruth,
                tol_m: float = WRONG_TRACK_TOL_M) -> tuple[np.ndarray, np.ndarray]:
    """Which links join different true points.

    Parameters
    ----------
    names : image name of each camera; keypoints : per camera ``(m, 2)`` OpenCV pixels
    links : :class:`pipeline.types.Links`

    Returns
    -------
    wrong, judged : ndarray, (L,) bool — ``wrong``: both ends judged and their true points
    farther apart than ``tol_m``; ``judged``: neither end on a depth edge
    """
    idx = truth.index()
    L = len(links)
    X = np.zeros((2, L, 3))
    ok = np.zeros((2, L), dtype=bool)
    for side, (cams, feats) in enumerate(((links.cam_i, links.feat_i),
                                          (links.cam_j, links.feat_j))):
        for k in np.unique(cams):
            sel = cams == k
            xy = np.asarray(keypoints[int(k)], dtype=np.float64)[feats[sel]]
            X[side, sel], ok[side, sel] = _true_points(truth, idx[names[int(k)]], xy)
    judged = ok.all(axis=0)
    wrong = judged & (np.linalg.norm(X[0] - X[1], axis=1) > tol_m)
    return wrong, judged
