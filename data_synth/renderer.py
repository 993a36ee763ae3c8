"""Exact, fast rendering of planar textured faces: image and z-depth per camera.

Each face is a plane, so the map from texture texels to image pixels is a homography and
``1/z`` is an affine function of the pixel ``(x, y)`` (for a ray ``z K⁻¹ p`` hitting the plane
``n·X = c``: ``1/z = nᵀK⁻¹p / c``). Per face and camera the renderer

1. culls back faces and clips the face polygon against the near plane,
2. picks a mip level of the texture from the texel footprint of one pixel,
3. warps the texture into the face's bounding box with ``cv2.warpPerspective``,
4. computes ``1/z`` analytically and the exact coverage of pixel centres by the projected
   face polygon (one ``x`` interval per row), and
5. composites by z-buffer (largest ``1/z`` wins).

Colour is rendered at ``supersample`` times the resolution and area-averaged down
(anti-aliasing); depth is computed the same way at native resolution, exactly at the pixel
centres. A little Gaussian sensor noise is added last.

Pixel convention: OpenCV (integer coordinates at pixel centres). Pixel ``x`` of the supersampled
grid has its centre at native coordinate ``(x + 0.5) / s - 0.5``.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["render_view", "project", "intrinsics"]

SKY = np.array([205, 218, 235], np.uint8)
NEAR = 0.05


def intrinsics(size: tuple[int, int], hfov_deg: float = 58.0) -> np.ndarray:
    """Pinhole ``K`` ``(3, 3)`` for image ``size = (W, H)`` with the principal point at the centre."""
    w, h = size
    f = (w / 2) / np.tan(np.deg2rad(hfov_deg) / 2)
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], np.float64)


def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points.

    Parameters
    ----------
    K, R, t : (3, 3), (3, 3), (3,) — ``x_cam = R X + t``
    X : (M, 3) world points

    Returns
    -------
    xy : (M, 2) float64 pixel coordinates (OpenCV convention)
    z : (M,) float64 depth in the camera frame
    """
    Xc = np.asarray(X, np.float64) @ R.T + t
    z = Xc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        p = Xc @ K.T
        xy = p[:, :2] / p[:, 2:3]
    return xy, z


def _clip_near(P: np.ndarray, near: float) -> np.ndarray:
    """Sutherland–Hodgman clip of a camera-frame polygon ``(k, 3)`` against ``z >= near``."""
    out = []
    k = len(P)
    for q in range(k):
        a, b = P[q], P[(q + 1) % k]
        ina, inb = a[2] >= near, b[2] >= near
        if ina:
            out.append(a)
        if ina != inb:
            s = (near - a[2]) / (b[2] - a[2])
            out.append(a + s * (b - a))
    return np.array(out) if out else np.zeros((0, 3))


def _face_roi(face, K, R, t, W, H):
    """Integer pixel box ``(x0, y0, x1, y1)`` (inclusive) covering the visible face, or None."""
    C = -R.T @ t
    if np.dot(face.normal, C - face.origin) <= 1e-9:  # back face (or edge-on)
        return None
    Pc = face.corners() @ R.T + t
    Pc = _clip_near(Pc, NEAR)
    if len(Pc) < 3:
        return None
    p = Pc @ K.T
    xy = p[:, :2] / p[:, 2:3]
    x0 = max(0, int(np.floor(xy[:, 0].min())))
    y0 = max(0, int(np.floor(xy[:, 1].min())))
    x1 = min(W - 1, int(np.ceil(xy[:, 0].max())))
    y1 = min(H - 1, int(np.ceil(xy[:, 1].max())))
    if x0 > x1 or y0 > y1:
        return None
    return x0, y0, x1, y1, xy


def _row_spans(poly: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Leftmost and rightmost ``x`` of a convex polygon ``(k, 2)`` on each row ``ys`` ``(R,)``.

    Rows that miss the polygon get ``(inf, -inf)``.
    """
    p, q = poly, np.roll(poly, -1, axis=0)
    dy = q[:, 1] - p[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = (ys[:, None] - p[None, :, 1]) / dy[None, :]
    hit = (tt >= 0) & (tt <= 1) & (dy[None, :] != 0)
    x = p[None, :, 0] + tt * (q[None, :, 0] - p[None, :, 0])
    xl = np.where(hit, x, np.inf).min(axis=1)
    xr = np.where(hit, x, -np.inf).max(axis=1)
    return xl, xr


def _plane_maps(face, K, R, t, poly, x0, y0, x1, y1):
    """Inverse depth and inside mask of a face over a pixel box, both ``(y1-y0+1, x1-x0+1)``.

    ``G = (K [R u, R v, R o + t])⁻¹`` maps a pixel to homogeneous face coordinates
    ``(a w, b w, w)`` with ``w = 1/z``. The pixel centre sees the face iff it lies inside the
    face's projected (near-clipped, convex) polygon ``poly`` ``(k, 2)`` — tested exactly per row
    as an ``x`` interval, which is the set ``w > 0, 0 ≤ a, b ≤ 1`` (minus points nearer than
    ``NEAR``) at a fraction of the cost.
    """
    M = K @ np.column_stack([R @ face.u, R @ face.v, R @ face.origin + t])
    g = np.linalg.inv(M)[2]
    xs = np.arange(x0, x1 + 1, dtype=np.float32)
    ys = np.arange(y0, y1 + 1, dtype=np.float64)
    # p = K X_cam / z = M (a, b, 1) / z, so G p = (a, b, 1) / z: the scale w is exactly 1/z
    invz = np.float32(g[0]) * xs + (g[1] * ys + g[2]).astype(np.float32)[:, None]
    xl, xr = _row_spans(poly, ys)
    mask = (xs >= xl.astype(np.float32)[:, None]) & (xs <= xr.astype(np.float32)[:, None])
    return invz, mask


def render_view(scene, K: np.ndarray, R: np.ndarray, t: np.ndarray, size: tuple[int, int],
                rng: np.random.Generator | None = None, supersample: int = 2,
                noise_sigma: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """Render one camera.

    Parameters
    ----------
    scene : data_synth.scene.Scene
    K : (3, 3) intrinsics; R : (3, 3), t : (3,) ``cam_from_world``
    size : (W, H)
    rng : numpy.random.Generator or None
        Sensor noise source; ``None`` renders without noise.
    supersample : int
        Colour is rendered at ``supersample x`` resolution and area-averaged (anti-aliasing).
    noise_sigma : float
        Standard deviation of the additive Gaussian noise in grey levels.

    Returns
    -------
    image : (H, W, 3) uint8 RGB
    depth : (H, W) float32, z in the camera frame, ``inf`` where no face is hit
    """
    W, H = size
    s = int(supersample)
    A = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1]])
    Ks = A @ K
    Ws, Hs = W * s, H * s
    color = np.empty((Hs, Ws, 3), np.uint8)
    color[:] = SKY
    zinv_s = np.zeros((Hs, Ws), np.float32)
    zinv = np.zeros((H, W), np.float32)
    for face in scene.faces:
        roi = _face_roi(face, K, R, t, W, H)
        if roi is None:
            continue
        x0, y0, x1, y1, poly = roi
        # exact depth at native pixel centres
        invz, mask = _plane_maps(face, K, R, t, poly, x0, y0, x1, y1)
        zr = zinv[y0:y1 + 1, x0:x1 + 1]
        cv2.copyTo(invz, (mask & (invz > zr)).view(np.uint8), zr)
        # colour at the supersampled grid
        X0, Y0, X1, Y1 = s * x0, s * y0, s * x1 + s - 1, s * y1 + s - 1
        poly_s = poly * s + (s - 1) / 2
        invz, mask = _plane_maps(face, Ks, R, t, poly_s, X0, Y0, X1, Y1)
        zr = zinv_s[Y0:Y1 + 1, X0:X1 + 1]
        upd = mask & (invz > zr)
        if not upd.any():
            continue
        centre = poly_s.mean(axis=0)
        level = _mip_level(face, Ks, R, t, np.array([centre[0], centre[1], 1.0]))
        tex = face.mip(level)
        th, tw = tex.shape[:2]
        # texel (j, i) -> face (a, b) = ((j + .5) / tw, (i + .5) / th) -> supersampled pixel
        Tex = np.array([[1 / tw, 0, 0.5 / tw], [0, 1 / th, 0.5 / th], [0, 0, 1]])
        M = Ks @ np.column_stack([R @ face.u, R @ face.v, R @ face.origin + t]) @ Tex
        M = np.array([[1, 0, -X0], [0, 1, -Y0], [0, 0, 1]]) @ M
        warped = cv2.warpPerspective(tex, M, (X1 - X0 + 1, Y1 - Y0 + 1), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_REPLICATE)
        m8 = upd.view(np.uint8)
        cv2.copyTo(invz, m8, zr)  # in place into the z-buffer view (masked copy, as np.copyto)
        cv2.copyTo(warped, m8, color[Y0:Y1 + 1, X0:X1 + 1])
    image = cv2.resize(color, (W, H), interpolation=cv2.INTER_AREA) if s > 1 else color
    if rng is not None and noise_sigma > 0:
        noise = rng.standard_normal(image.shape, dtype=np.float32) * np.float32(noise_sigma)
        image = np.clip(image.astype(np.float32) + noise, 0, 255).astype(np.uint8)
    with np.errstate(divide="ignore"):
        depth = np.where(zinv > 0, 1.0 / zinv, np.inf).astype(np.float32)
    return image, depth


def _mip_level(face, Ks, R, t, p_centre: np.ndarray) -> int:
    """Mip level so that one (supersampled) pixel covers about one texel at ``p_centre``.

    Texels per pixel = largest singular value of the Jacobian of pixel -> texel at the centre of
    the visible face (isotropic mip mapping; the floor tiles are small enough that the footprint
    varies little within one tile).
    """
    th, tw = face.texture.shape[:2]
    M = Ks @ np.column_stack([R @ face.u, R @ face.v, R @ face.origin + t])
    G = np.diag([tw, th, 1.0]) @ np.linalg.inv(M)  # pixel -> texel (homogeneous)
    q = G @ p_centre
    if abs(q[2]) < 1e-12:
        return 0
    x, y = q[0] / q[2], q[1] / q[2]
    J = (G[:2, :2] - np.outer([x, y], G[2, :2])) / q[2]
    smax = float(np.linalg.svd(J, compute_uv=False)[0])
    if not np.isfinite(smax) or smax <= 1.0:
        return 0
    return int(np.floor(np.log2(smax)))
