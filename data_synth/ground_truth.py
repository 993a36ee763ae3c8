"""Ground truth for rendered formations: 3D points of keypoints, good links, true pairs.

Implements the definitions of docs/DESIGN.md (synthetic data only), which give the paper's Table I rows
"good links", "spurious links" and "missing links" (Aragüés et al., Sec. V-A) for the image
experiment of Sec. V-B, where the paper itself had no ground truth:

* **good link** ``((i, r), (j, s))``: both keypoints image the same surface point — the 3D point
  of one keypoint (from its camera's depth map) reprojects within ``tol_px`` (default 2 px) of
  the other keypoint **and** is visible in the other camera (depth test). The test is made in
  both directions and a link is good if either direction passes; near depth edges one of the
  two keypoints may have no reliable depth.
* **depth test**: a world point with depth ``z`` in camera ``j`` projecting to ``p`` is visible
  iff ``p`` lies in the image and ``|depth_j(p) - z| <= DEPTH_EPS * z`` (``DEPTH_EPS = 0.02``,
  i.e. 2 % of the depth: 10 cm at 5 m), with ``depth_j`` sampled as in
  :func:`sample_depth`.
* **true pairs** of a communication edge: the good pairs between detected keypoints made
  one-to-one by mutual nearest reprojection distance; **missing links** are true pairs that
  matching did not return (counted per link set by :mod:`pipeline.evaluation.links`).

Depth is sampled with bilinear interpolation of ``1/z`` (exact on a plane, where ``1/z`` is
affine in the pixel) when the four neighbouring pixels lie on one plane, else from the nearest
pixel.
"""

from __future__ import annotations

import hashlib
import numbers

import numpy as np
from scipy.spatial import cKDTree

from data_synth.renderer import project
from pipeline.errors import InputError
from pipeline.types import View

__all__ = [
    "DEPTH_EPS",
    "sample_depth",
    "points_from_keypoints",
    "reprojection_errors",
    "good_links",
    "true_pairs",
]

DEPTH_EPS = 0.02
"""Relative depth tolerance of the visibility test."""


def _check_tol(tol_px) -> float:
    """``tol_px`` as a float, or InputError naming it unless it is a finite number > 0."""
    if (isinstance(tol_px, bool) or not isinstance(tol_px, numbers.Real)
            or not np.isfinite(tol_px) or tol_px <= 0):
        raise InputError(f"tol_px must be a finite number of pixels > 0, got {tol_px!r}")
    return float(tol_px)


def _check_xy(xy, what: str) -> np.ndarray:
    a = np.asarray(xy, np.float64)
    if a.ndim != 2 or a.shape[1] != 2:
        raise InputError(f"{what} must have shape (M, 2), got {a.shape}")
    return a


def _inverse_depth(z: np.ndarray) -> np.ndarray:
    """``1/z`` in float64, ``0`` where ``z`` is not finite (no surface hit); elementwise, so
    only the sampled pixels of a depth map are ever converted."""
    z = z.astype(np.float64)
    with np.errstate(divide="ignore"):
        return np.where(np.isfinite(z), 1.0 / z, 0.0)


def sample_depth(depth: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Depth at sub-pixel positions, ``inf`` outside the image or where nothing was hit.

    Parameters
    ----------
    depth : (H, W) float32
    xy : (M, 2) pixel coordinates (OpenCV convention)

    Returns
    -------
    (M,) float64
    """
    H, W = depth.shape
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    out = np.full(len(xy), np.inf)
    x, y = xy[:, 0], xy[:, 1]
    inside = (x >= -0.5) & (x <= W - 0.5) & (y >= -0.5) & (y <= H - 0.5)
    if not inside.any():
        return out
    x, y = x[inside], y[inside]
    ix = np.clip(np.rint(x).astype(np.int64), 0, W - 1)
    iy = np.clip(np.rint(y).astype(np.int64), 0, H - 1)
    x0 = np.clip(np.floor(x).astype(np.int64), 0, W - 2)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, H - 2)
    fx, fy = np.clip(x - x0, 0, 1), np.clip(y - y0, 0, 1)
    # the nearest pixel and the four around the point, read and converted in one go
    inv = _inverse_depth(depth[np.stack([iy, y0, y0, y0 + 1, y0 + 1]),
                               np.stack([ix, x0, x0 + 1, x0, x0 + 1])])
    nearest, q = inv[0], inv[1:]
    q00, q10, q01, q11 = q
    lo, hi = q.min(axis=0), q.max(axis=0)
    # one plane: all hit, close in depth, and affine (q00 + q11 = q10 + q01)
    planar = (lo > 0) & (hi - lo <= 0.05 * hi) & (np.abs(q00 + q11 - q10 - q01) <= 1e-3 * hi)
    bil = (q00 * (1 - fx) * (1 - fy) + q10 * fx * (1 - fy) + q01 * (1 - fx) * fy + q11 * fx * fy)
    inv_s = np.where(planar, bil, nearest)
    with np.errstate(divide="ignore"):
        out[inside] = np.where(inv_s > 0, 1.0 / inv_s, np.inf)
    return out


def points_from_keypoints(view: View, xy) -> tuple[np.ndarray, np.ndarray]:
    """World 3D point imaged at each keypoint, from the view's depth map.

    Parameters
    ----------
    view : pipeline.types.View
        Needs ``depth``, ``K``, ``R``, ``t``.
    xy : (M, 2) keypoint pixel coordinates

    Returns
    -------
    xyz : (M, 3) float64 world points (``nan`` where invalid)
    valid : (M,) bool — the keypoint is inside the image and its pixel hit a surface
    """
    if view.depth is None or view.R is None:
        raise InputError(f"view {view.name!r} has no depth/pose: ground truth needs a rendered view")
    xy = _check_xy(xy, "xy")
    z = sample_depth(view.depth, xy)
    valid = np.isfinite(z)
    rays = np.column_stack([xy, np.ones(len(xy))]) @ np.linalg.inv(view.K).T
    Xc = rays * np.where(valid, z, np.nan)[:, None]
    xyz = (Xc - view.t) @ view.R  # R^T (Xc - t)
    return xyz, valid


def _transfer(src: View, xy_src: np.ndarray, dst: View,
              points: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Project keypoints of ``src`` into ``dst``: ``(M, 2)`` pixels and ``(M,)`` visibility.

    ``points``: ``points_from_keypoints(src, xy_src)`` when the caller already has it."""
    X, valid = points_from_keypoints(src, xy_src) if points is None else points
    p, z = project(dst.K, dst.R, dst.t, np.nan_to_num(X))
    d = sample_depth(dst.depth, p)
    visible = valid & (z > 0) & np.isfinite(d) & (np.abs(d - z) <= DEPTH_EPS * np.abs(z))
    return p, visible


def reprojection_errors(formation, i: int, xy_i, j: int, xy_j) -> np.ndarray:
    """Symmetric transfer error of row-aligned keypoint pairs, ``(M,)`` pixels.

    The smaller of the two directions (``i -> j`` and ``j -> i``) among those where the source
    point has depth and is visible in the target (depth test); ``inf`` if neither is.
    """
    vi, vj = _view(formation, i), _view(formation, j)
    xy_i, xy_j = _check_xy(xy_i, "xy_i"), _check_xy(xy_j, "xy_j")
    if len(xy_i) != len(xy_j):
        raise InputError(f"xy_i and xy_j must pair up row by row: {len(xy_i)} != {len(xy_j)}")
    p_ij, vis_ij = _transfer(vi, xy_i, vj)
    p_ji, vis_ji = _transfer(vj, xy_j, vi)
    e_ij = np.where(vis_ij, np.linalg.norm(p_ij - xy_j, axis=1), np.inf)
    e_ji = np.where(vis_ji, np.linalg.norm(p_ji - xy_i, axis=1), np.inf)
    return np.minimum(e_ij, e_ji)


def good_links(formation, cam_i: int, xy_i, cam_j: int, xy_j, tol_px: float = 2.0) -> np.ndarray:
    """Which keypoint pairs are good links (docs/DESIGN.md), ``(M,)`` bool.

    Parameters
    ----------
    formation : data_synth.Formation
    cam_i, cam_j : int — cameras
    xy_i, xy_j : (M, 2) — row ``k`` is the pair ``(xy_i[k], xy_j[k])``
    tol_px : float — reprojection tolerance in pixels (default 2)

    Notes
    -----
    Good iff in at least one direction the source keypoint has depth, its 3D point passes the
    depth test in the other camera (relative tolerance ``DEPTH_EPS = 2 %``) and reprojects
    within ``tol_px`` of the other keypoint.
    """
    tol_px = _check_tol(tol_px)
    return reprojection_errors(formation, cam_i, xy_i, cam_j, xy_j) <= tol_px


def _view(formation, i) -> View:
    n = len(formation.views)
    if isinstance(i, bool) or not isinstance(i, numbers.Integral) or not 0 <= i < n:
        raise InputError(f"camera {i!r} is not a camera of the formation; cameras are 0..{n - 1}")
    return formation.views[int(i)]


def _candidates(src: View, xy_src, dst: View, xy_dst, tol_px: float, k: int = 4, *,
                src_points=None, dst_tree=None):
    """(src index, dst index, distance) of reprojections within ``tol_px``.

    ``src_points`` (``points_from_keypoints(src, xy_src)``) and ``dst_tree``
    (``cKDTree(xy_dst)``): when the caller already has them."""
    if len(xy_src) == 0 or len(xy_dst) == 0:
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0)
    p, vis = _transfer(src, xy_src, dst, src_points)
    tree = cKDTree(xy_dst) if dst_tree is None else dst_tree
    kk = min(k, len(xy_dst))
    seen = np.flatnonzero(vis)  # only visible reprojections can be candidates
    d, idx = tree.query(p[seen], k=kk, distance_upper_bound=tol_px)
    d, idx = d.reshape(len(seen), kk), idx.reshape(len(seen), kk)
    ok = np.isfinite(d)
    rows = np.repeat(seen, kk).reshape(len(seen), kk)
    return rows[ok], idx[ok], d[ok]


def true_pairs(formation, i: int, xy_i, j: int, xy_j, tol_px: float = 2.0) -> np.ndarray:
    """The good one-to-one pairs between detected keypoints of cameras ``i`` and ``j``.

    Every pair whose symmetric reprojection error (see :func:`reprojection_errors`) is within
    ``tol_px`` is a candidate; a candidate ``(r, s)`` is kept when ``s`` is the best candidate of
    ``r`` and ``r`` the best of ``s`` (mutual nearest), which makes the result one-to-one.

    Parameters
    ----------
    formation : data_synth.Formation
    i, j : int — cameras
    xy_i : (N_i, 2), xy_j : (N_j, 2) — all detected keypoints of each camera

    Returns
    -------
    (P, 2) int64 — rows ``(r, s)``, sorted by ``r``
    """
    vi, vj = _view(formation, i), _view(formation, j)
    xy_i, xy_j = _check_xy(xy_i, "xy_i"), _check_xy(xy_j, "xy_j")
    tol_px = _check_tol(tol_px)
    # evaluation asks for the pairs of one camera pair several times (the links before and
    # after each stage, each baseline): computed once per formation, cameras, keypoints, tol
    cache = getattr(formation, "_truth_cache", None)
    key = ("true_pairs", int(i), int(j), float(tol_px), _fingerprint(xy_i), _fingerprint(xy_j))
    if cache is not None and key in cache:
        return cache[key].copy()
    pairs = _true_pairs(vi, xy_i, vj, xy_j, tol_px,
                        _camera_geometry(formation, i, xy_i), _camera_geometry(formation, j, xy_j))
    if cache is not None:
        cache[key] = pairs.copy()
    return pairs


def _fingerprint(a: np.ndarray) -> tuple:
    """Shape, dtype and a digest of the bytes of ``a``: equal iff the contents are equal."""
    return a.shape, a.dtype.str, hashlib.blake2b(np.ascontiguousarray(a).tobytes(),
                                                  digest_size=16).digest()


def _camera_geometry(formation, i: int, xy: np.ndarray) -> dict:
    """What :func:`true_pairs` needs of camera ``i``'s keypoints ``xy`` whatever the other
    camera: their world points (:func:`points_from_keypoints`) and a k-d tree of them, built
    on first use and kept with the formation (``_camera_cache``) when it has one."""
    cache = getattr(formation, "_camera_cache", None)
    key = (int(i), _fingerprint(xy))
    if cache is not None and key in cache:
        return cache[key]
    view = _view(formation, i)
    geometry = {"points": points_from_keypoints(view, xy) if len(xy) else None,
                "tree": cKDTree(xy) if len(xy) else None}
    if cache is not None:
        cache[key] = geometry
    return geometry


def _true_pairs(vi: View, xy_i: np.ndarray, vj: View, xy_j: np.ndarray,
                tol_px: float, geo_i: dict | None = None, geo_j: dict | None = None) -> np.ndarray:
    """:func:`true_pairs` on validated input, ``(P, 2)`` int64 (``geo_i``, ``geo_j``: the
    cameras' :func:`_camera_geometry`, when the caller has it)."""
    geo_i, geo_j = geo_i or {}, geo_j or {}
    r1, s1, d1 = _candidates(vi, xy_i, vj, xy_j, tol_px, src_points=geo_i.get("points"),
                             dst_tree=geo_j.get("tree"))
    s2, r2, d2 = _candidates(vj, xy_j, vi, xy_i, tol_px, src_points=geo_j.get("points"),
                             dst_tree=geo_i.get("tree"))
    r = np.concatenate([r1, r2])
    s = np.concatenate([s1, s2])
    d = np.concatenate([d1, d2])
    if r.size == 0:
        return np.zeros((0, 2), np.int64)
    # best candidate per r and per s (ties broken by index, deterministic)
    order = np.lexsort((s, d, r))
    first = np.r_[True, r[order][1:] != r[order][:-1]]
    best_s_of_r = np.full(len(xy_i), -1, np.int64)
    best_s_of_r[r[order][first]] = s[order][first]
    order = np.lexsort((r, d, s))
    first = np.r_[True, s[order][1:] != s[order][:-1]]
    rs, ss = r[order][first], s[order][first]
    keep = best_s_of_r[rs] == ss
    pairs = np.column_stack([rs[keep], ss[keep]]).astype(np.int64)
    return pairs[np.argsort(pairs[:, 0], kind="stable")]
