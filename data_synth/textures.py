"""Deterministic procedural textures for the synthetic scene.

The paper's image experiment (Aragüés et al., Sec. V-B) matches SURF features of real photos in
which, after the epipolar test, "some spurious associations are still found". In man-made scenes
repeated structure is a usual cause, so these textures are rich in blob- and corner-like detail
for SIFT and hold **repeated structure** — a grid of windows in a few near-identical variants,
bricks, floor tiles drawn from a few motifs, crates that share one stencil — next to unique
detail (posters, stains, plaster noise) that lets the correct epipolar geometry win RANSAC.

Every function takes a ``numpy.random.Generator`` and returns an ``(H, W, 3) uint8`` RGB image;
the same generator state gives the same texture bit for bit.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = [
    "value_noise",
    "facade_texture",
    "floor_texture",
    "crate_texture",
    "side_wall_texture",
]


def value_noise(rng: np.random.Generator, shape: tuple[int, int], cell: float,
                octaves: int = 4, persistence: float = 0.55) -> np.ndarray:
    """Fractal value noise in ``[0, 1]``.

    Parameters
    ----------
    rng : numpy.random.Generator
    shape : (H, W)
    cell : float
        Size in texels of the coarsest noise cell.
    octaves : int
        Number of octaves; each halves the cell size.
    persistence : float
        Amplitude ratio between consecutive octaves.

    Returns
    -------
    ndarray, (H, W) float32
    """
    h, w = shape
    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for k in range(octaves):
        c = max(cell / 2 ** k, 1.0)
        gh, gw = int(np.ceil(h / c)) + 2, int(np.ceil(w / c)) + 2
        grid = rng.random((gh, gw), dtype=np.float32)
        up = cv2.resize(grid, (int(gw * c), int(gh * c)), interpolation=cv2.INTER_CUBIC)
        out += amp * up[:h, :w]
        total += amp
        amp *= persistence
    out /= total
    lo, hi = float(out.min()), float(out.max())
    return (out - lo) / max(hi - lo, 1e-6)


def _tint(gray: np.ndarray, color) -> np.ndarray:
    """``(H, W)`` in ``[0, 1]`` times an RGB colour -> ``(H, W, 3)`` float32."""
    return gray[..., None] * np.asarray(color, np.float32)[None, None, :]


def _to_u8(img: np.ndarray) -> np.ndarray:
    return np.clip(img, 0, 255).astype(np.uint8)


def _random_blobs(rng: np.random.Generator, img: np.ndarray, n: int, rmin: float, rmax: float,
                  alpha: float = 1.0) -> None:
    """Draw ``n`` anti-aliased ellipses of random colour in place (unique detail for SIFT)."""
    h, w = img.shape[:2]
    over = img.copy()
    for _ in range(n):
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        ax = rng.uniform(rmin, rmax)
        ay = ax * rng.uniform(0.4, 1.0)
        ang = rng.uniform(0, 180)
        col = tuple(float(c) for c in rng.uniform(20, 235, 3))
        cv2.ellipse(over, (int(cx * 16), int(cy * 16)), (int(ax * 16), int(ay * 16)), ang, 0, 360,
                    col, -1, cv2.LINE_AA, 4)
    cv2.addWeighted(over, alpha, img, 1 - alpha, 0, dst=img)


def _poster(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A unique, busy rectangle (a poster / sign): blobs, lines and noise."""
    base = _tint(value_noise(rng, (h, w), cell=max(h, w) / 3, octaves=3), rng.uniform(90, 230, 3))
    img = np.ascontiguousarray(base, np.float32)
    _random_blobs(rng, img, n=int(6 + h * w / 600), rmin=2, rmax=max(4, min(h, w) / 5))
    for _ in range(int(3 + w / 20)):
        p0 = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        p1 = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        cv2.line(img, p0, p1, tuple(float(c) for c in rng.uniform(0, 255, 3)),
                 int(rng.integers(1, 4)), cv2.LINE_AA)
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), (30, 30, 30), 2)
    return img


def _window_template(rng: np.random.Generator, h: int, w: int, variant: int = 0) -> np.ndarray:
    """One window: dark frame, light sill, 2x3 panes with a glass gradient and cross bars.

    ``variant`` adds a decoration behind the glass — 0 none, 1 a dotted curtain, 2 a flower pot
    on the sill, 3 a half-lowered blind — drawn from ``rng``: windows of one variant are
    near-copies, windows of different variants share only the frame.
    """
    img = np.zeros((h, w, 3), np.float32)
    img[:] = (70, 60, 55)  # frame
    fr = max(2, w // 14)
    glass = np.linspace(0, 1, h - 2 * fr, dtype=np.float32)[:, None] * np.ones((1, w - 2 * fr), np.float32)
    glass = 0.55 * glass + 0.45 * value_noise(rng, glass.shape, cell=w / 3, octaves=2)
    img[fr:h - fr, fr:w - fr] = _tint(glass, (110, 140, 170)) + 30
    v = variant % 4
    if v == 1:
        cw = int(rng.uniform(0.3, 0.5) * (w - 2 * fr))
        col = rng.uniform(120, 240, 3)
        img[fr:h - fr, fr:fr + cw] = col * (0.85 + 0.15 * value_noise(rng, (h - 2 * fr, cw), cell=6)[..., None])
        for _ in range(int(h * cw / 150)):
            p = (int(16 * (fr + rng.uniform(0, cw))), int(16 * (fr + rng.uniform(0, h - 2 * fr))))
            cv2.circle(img, p, int(16 * rng.uniform(1.5, 3.5)), tuple(float(c) for c in col * 0.4), -1,
                       cv2.LINE_AA, 4)
    elif v == 2:
        px = int(rng.uniform(0.25, 0.75) * w)
        base = h - fr - max(3, h // 16)
        for _ in range(12):
            p = (int(16 * (px + rng.normal(0, w / 12))), int(16 * (base - h * 0.12 + rng.normal(0, h / 14))))
            cv2.circle(img, p, int(16 * rng.uniform(2, 6)),
                       tuple(float(c) for c in rng.uniform([20, 90, 20], [120, 200, 90])), -1, cv2.LINE_AA, 4)
        cv2.rectangle(img, (px - w // 10, base - h // 10), (px + w // 10, base), (150, 70, 40), -1)
    elif v == 3:
        depth = int(rng.uniform(0.25, 0.5) * (h - 2 * fr))
        for y in range(fr, fr + depth, 4):
            img[y:y + 3, fr:w - fr] = (225, 220, 205)
    bar = max(2, w // 24)
    for k in (1, 2):  # two horizontal bars -> 3 rows of panes
        y = fr + k * (h - 2 * fr) // 3
        img[y - bar // 2:y + (bar + 1) // 2, fr:w - fr] = (200, 195, 185)
    x = w // 2
    img[fr:h - fr, x - bar // 2:x + (bar + 1) // 2] = (200, 195, 185)
    sill = max(3, h // 16)
    img[h - sill:h, :] = (215, 210, 200)
    # a small handle and a ventilation slot: corner-like detail shared by every copy
    cv2.circle(img, (x + 2 * bar, h // 2), max(2, w // 30), (40, 40, 40), -1, cv2.LINE_AA)
    cv2.rectangle(img, (fr + 3, fr + 3), (fr + 3 + w // 6, fr + 3 + h // 20), (60, 70, 80), -1)
    return img


def facade_texture(rng: np.random.Generator, width_m: float, height_m: float, px_per_m: float,
                   rows: int, cols: int, window_variation: float = 6.0,
                   stains_per_m2: float = 1.5, roughness: float = 0.0,
                   window_variants: int = 1) -> np.ndarray:
    """Building facade: plaster noise, string courses, a ``rows x cols`` window grid, posters.

    Each window is one of ``window_variants`` templates (see :func:`_window_template`) plus a
    little per-window noise (``window_variation`` grey levels), so features on one window also
    match another window of the same variant in the row — repeated structure along the
    epipolar lines of a line-abreast formation, which lets wrong matches survive RANSAC.
    ``stains_per_m2`` sets the density of unique low-contrast blobs, ``roughness`` the amplitude
    of a fine unique grit (0: none).

    Returns
    -------
    ndarray, (round(height_m * px_per_m), round(width_m * px_per_m), 3) uint8
        Row 0 is the top of the facade.
    """
    H, W = int(round(height_m * px_per_m)), int(round(width_m * px_per_m))
    plaster = 0.65 * value_noise(rng, (H, W), cell=px_per_m * 1.5) + \
        0.35 * value_noise(rng, (H, W), cell=px_per_m * 0.08, octaves=2)
    img = _tint(0.35 + 0.5 * plaster, (225, 205, 180))
    # bricks in the lower band (another repetition, finer scale)
    ground_h = int(0.18 * H)
    bh, bw = max(4, int(px_per_m * 0.12)), max(8, int(px_per_m * 0.3))
    yb0 = H - ground_h
    for r, y in enumerate(range(yb0, H, bh)):
        off = (r % 2) * bw // 2
        for x in range(-off, W, bw):
            shade = rng.uniform(0.75, 1.0)
            cv2.rectangle(img, (x + 1, y + 1), (x + bw - 2, y + bh - 2),
                          (150 * shade, 80 * shade, 60 * shade), -1)
    if roughness > 0:  # fine grit over plaster and bricks: many small, unique blobs for SIFT
        grit = value_noise(rng, (H, W), cell=px_per_m * 0.05, octaves=2) - 0.5
        img *= (1 + roughness * grit)[..., None]
    # string courses between storeys
    storey = (H - ground_h) / rows
    for k in range(rows + 1):
        y = int(k * storey)
        img[max(0, y - 3):y + 3] = (190, 180, 170)
    win_h, win_w = int(storey * 0.55), int(W / cols * 0.5)
    templates = [_window_template(rng, win_h, win_w, k) for k in range(window_variants)]
    for r in range(rows):
        for c in range(cols):
            template = templates[int(rng.integers(window_variants))]
            y0 = int(r * storey + storey * 0.22)
            x0 = int((c + 0.5) * W / cols - win_w / 2)
            noise = (rng.standard_normal((win_h // 8 + 1, win_w // 8 + 1)).astype(np.float32)
                     * window_variation)
            noise = cv2.resize(noise, (win_w, win_h), interpolation=cv2.INTER_LINEAR)
            img[y0:y0 + win_h, x0:x0 + win_w] = template + noise[..., None]
    # unique posters / signs between the windows and on the ground band
    for _ in range(max(3, cols // 2 + rows)):
        ph, pw = int(rng.uniform(0.4, 0.9) * px_per_m), int(rng.uniform(0.4, 1.1) * px_per_m)
        y0 = int(rng.uniform(0, H - ph))
        x0 = int(rng.uniform(0, W - pw))
        img[y0:y0 + ph, x0:x0 + pw] = _poster(rng, ph, pw)
    # stains: low-alpha unique blobs over everything
    _random_blobs(rng, img, n=int(W * H / (px_per_m ** 2) * stains_per_m2), rmin=px_per_m * 0.03,
                  rmax=px_per_m * 0.15, alpha=0.35)
    return _to_u8(img)


def _tile_motif(rng: np.random.Generator, n: int) -> np.ndarray:
    """One ``n x n`` floor-tile motif: a rosette of discs and bars on a glazed background."""
    base = _tint(0.6 + 0.4 * value_noise(rng, (n, n), cell=n / 2, octaves=2), rng.uniform(120, 230, 3))
    img = np.ascontiguousarray(base)
    c = n / 2
    col = tuple(float(v) for v in rng.uniform(20, 160, 3))
    k = int(rng.integers(3, 7))
    for q in range(k):
        a = 2 * np.pi * q / k + rng.uniform(0, 0.3)
        rr = n * rng.uniform(0.18, 0.32)
        p = (int(16 * (c + rr * np.cos(a))), int(16 * (c + rr * np.sin(a))))
        cv2.circle(img, p, int(16 * n * rng.uniform(0.04, 0.09)), col, -1, cv2.LINE_AA, 4)
    cv2.circle(img, (int(16 * c), int(16 * c)), int(16 * n * 0.1),
               tuple(float(v) for v in rng.uniform(20, 235, 3)), -1, cv2.LINE_AA, 4)
    return img


def floor_texture(rng: np.random.Generator, width_m: float, depth_m: float, px_per_m: float,
                  tile_m: float = 0.5, n_motifs: int = 3, dirt: float = 0.25,
                  stains_per_m2: float = 0.8) -> np.ndarray:
    """Tiled floor: tiles drawn from ``n_motifs`` motifs (random rotation), grout, dirt.

    Returns
    -------
    ndarray, (round(depth_m * px_per_m), round(width_m * px_per_m), 3) uint8
    """
    H, W = int(round(depth_m * px_per_m)), int(round(width_m * px_per_m))
    n = int(round(tile_m * px_per_m))
    motifs = [_tile_motif(rng, n) for _ in range(n_motifs)]
    img = np.empty((H, W, 3), np.float32)
    img[:] = (90, 85, 80)
    grout = max(1, n // 25)
    for ty in range(0, H, n):
        for tx in range(0, W, n):
            m = motifs[int(rng.integers(n_motifs))]
            m = np.rot90(m, int(rng.integers(4)))
            hh, ww = min(n, H - ty) - grout, min(n, W - tx) - grout
            if hh > 0 and ww > 0:
                img[ty + grout:ty + grout + hh, tx + grout:tx + grout + ww] = m[:hh, :ww]
    stains = value_noise(rng, (H, W), cell=px_per_m * 1.0)
    img *= (1 - dirt + dirt * stains)[..., None]
    _random_blobs(rng, img, n=int(W * H / (px_per_m ** 2) * stains_per_m2), rmin=px_per_m * 0.02,
                  rmax=px_per_m * 0.08, alpha=0.5)
    return _to_u8(img)


def crate_texture(rng: np.random.Generator, logo_rng: np.random.Generator, w: int, h: int,
                  variation: float = 8.0) -> np.ndarray:
    """Wooden crate side: planks, a frame, and a stencil logo shared by all crates.

    Parameters
    ----------
    rng : numpy.random.Generator
        Per-crate randomness (wood grain, small variation).
    logo_rng : numpy.random.Generator
        Seeded identically for every crate, so all crates carry the same stencil (repetition).
    w, h : int
        Texture size in texels.
    """
    grain = value_noise(rng, (h, w * 4), cell=h / 2, octaves=3)
    grain = cv2.resize(grain, (w, h), interpolation=cv2.INTER_AREA)  # stretched: wood fibres
    img = _tint(0.55 + 0.45 * grain, (190, 140, 90))
    planks = 5
    for k in range(1, planks):
        y = k * h // planks
        img[y - 1:y + 1] *= 0.45
    fr = max(3, w // 12)
    img[:fr] *= 0.7
    img[-fr:] *= 0.7
    img[:, :fr] *= 0.7
    img[:, -fr:] *= 0.7
    # stencil logo: identical geometry on every crate
    logo = np.zeros((h, w), np.uint8)
    for _ in range(5):
        kind = int(logo_rng.integers(3))
        cx, cy = logo_rng.uniform(0.3, 0.7) * w, logo_rng.uniform(0.3, 0.7) * h
        s = logo_rng.uniform(0.06, 0.16) * w
        if kind == 0:
            cv2.circle(logo, (int(cx), int(cy)), int(s), 255, -1, cv2.LINE_AA)
        elif kind == 1:
            cv2.rectangle(logo, (int(cx - s), int(cy - s / 2)), (int(cx + s), int(cy + s / 2)), 255, -1)
        else:
            pts = np.array([[cx, cy - s], [cx + s, cy + s], [cx - s, cy + s]], np.int32)
            cv2.fillConvexPoly(logo, pts, 255, cv2.LINE_AA)
    ink = logo.astype(np.float32)[..., None] / 255.0
    img = img * (1 - 0.8 * ink) + ink * 0.8 * np.array([20, 20, 25], np.float32)
    img += rng.standard_normal(3).astype(np.float32) * variation
    return _to_u8(img)


def side_wall_texture(rng: np.random.Generator, width_m: float, height_m: float,
                      px_per_m: float) -> np.ndarray:
    """A plain concrete wall with a few unique posters (context, not repetition)."""
    H, W = int(round(height_m * px_per_m)), int(round(width_m * px_per_m))
    img = _tint(0.4 + 0.45 * value_noise(rng, (H, W), cell=px_per_m), (170, 170, 165))
    img = np.ascontiguousarray(img)
    for _ in range(3):
        ph, pw = int(rng.uniform(0.5, 1.0) * px_per_m), int(rng.uniform(0.5, 1.0) * px_per_m)
        y0, x0 = int(rng.uniform(0, H - ph)), int(rng.uniform(0, W - pw))
        img[y0:y0 + ph, x0:x0 + pw] = _poster(rng, ph, pw)
    _random_blobs(rng, img, n=int(W * H / (px_per_m ** 2)), rmin=px_per_m * 0.03,
                  rmax=px_per_m * 0.12, alpha=0.4)
    return _to_u8(img)
