"""A scene of repeated structure seen by a ring of cameras, written as a folder of photographs
with its exact truth.

The scene: a square tower of repeated modules (each side a grid of identical windows); its
sides carry four facades (``sides="ABCD"``) or copies of fewer: with ``"AABB"`` two adjacent
sides are exact copies (the same windows, posters and stains), and so are the other two. It stands on a tiled floor drawn from a few
motifs (repeated textures, with unique dirt). A ring of cameras walks round it at eye height,
all looking at its centre. A camera at the corner of the two A sides sees both copies at once;
another camera sees one A side where the first saw the other, so matches between them that
join different true points survive two-view verification, and a cycle through a third view
brings two different features of one image into one set: what the consistency stage detects
(Aragüés et al., Sec. III).

Measured while building it: with four identical sides (a four-fold symmetric object) COLMAP
folded the ring onto half of itself (cameras half a turn apart put at one pose) and cleaning
could not help: a camera never sees two opposite sides, so the fold joins no two features of
one image and is a *consistent* association, invisible to the consistency stage.

:func:`write_ring_folder` writes ``cam00.png`` … (no ``K.txt``: a COLMAP user's photos come
without calibration) and ``truth.npz``: per image its name, ``K`` (OpenCV pixel convention),
``cam_from_world`` ``R, t`` and the depth of every pixel (``inf`` for the sky), from which the
true 3D point of any pixel follows (:mod:`pipeline.evaluation.scene_truth`).
"""

from __future__ import annotations

import functools
from pathlib import Path

import cv2
import numpy as np

from data_synth import textures
from data_synth.formations import look_at
from data_synth.renderer import intrinsics, render_view
from data_synth.scene import Scene, tiled_faces

__all__ = ["build_tower_scene", "ring_poses", "write_ring_folder", "TOWER_SIDE_M",
           "TOWER_HEIGHT_M"]

#: side and height of the tower (metres)
TOWER_SIDE_M, TOWER_HEIGHT_M = 4.0, 6.0


@functools.lru_cache(maxsize=4)
def build_tower_scene(seed: int = 0, sides: str = "ABCD", floor_motifs: int = 8,
                      floor_dirt: float = 0.6, floor_stains: float = 2.0) -> Scene:
    """The tower (four identical sides) on its tiled floor, deterministic for ``seed``.

    World frame: ``Z`` up, metres; the tower stands on ``z = 0`` centred on the origin, its
    sides facing ``-y, +x, +y, -x`` carry the facades named by the letters of ``sides``
    (``"ABCD"``: four facades, each a grid of identical windows; ``"AABB"``: two adjacent
    sides exact copies of each other; ``"AAAA"``: a four-fold symmetric object); the floor
    spans ``[-14, 14]²``. The floor's tiles
    (``floor_motifs`` motifs, ``floor_dirt``, ``floor_stains`` unique stains per m²) are
    what tells the sides apart: with 3 motifs and little dirt the whole scene is nearly
    four-fold symmetric and COLMAP folds every quarter turn of the ring onto one pose.
    """
    rng = np.random.default_rng([seed, 25])
    ppm = 100.0
    s, h = TOWER_SIDE_M, TOWER_HEIGHT_M
    if len(sides) != 4 or not sides.isalpha():
        raise ValueError(f"sides {sides!r}: four letters, one facade per letter (e.g. ABCD)")
    facades = {c: textures.facade_texture(rng, s, h, ppm, rows=3, cols=3, window_variation=2.0,
                                          stains_per_m2=0.5, window_variants=1)
               for c in sorted(set(sides))}
    half = s / 2
    faces: list = []
    # each side seen upright from outside: origin = its top-left corner, u rightwards, v down;
    # one facade per letter of ``sides``: equal letters are exact copies
    for k, ((origin, u), side) in enumerate(zip((
            ([-half, -half, h], [s, 0, 0]),     # side facing -y
            ([half, -half, h], [0, s, 0]),      # side facing +x
            ([half, half, h], [-s, 0, 0]),      # side facing +y
            ([-half, half, h], [0, -s, 0])),   # side facing -x
            [facades[c] for c in sides], strict=True)):
        faces += tiled_faces(f"tower{k}", origin, u, [0, 0, -h], side)
    roof = textures.side_wall_texture(rng, s, s, ppm)
    faces += tiled_faces("roof", [-half, half, h], [s, 0, 0], [0, -s, 0], roof)
    floor = textures.floor_texture(rng, 28.0, 28.0, 40.0, tile_m=0.5, n_motifs=floor_motifs,
                                   dirt=floor_dirt, stains_per_m2=floor_stains)
    faces += tiled_faces("floor", [-14.0, 14.0, 0.0], [28.0, 0, 0], [0, -28.0, 0], floor)
    corners = {}
    for q, (x, y) in enumerate(((-half, -half), (half, -half), (half, half), (-half, half))):
        corners[f"tower.top{q}"] = np.array([x, y, h], np.float64)
        corners[f"tower.foot{q}"] = np.array([x, y, 0.0], np.float64)
    return Scene(faces=faces, landmarks=corners, seed=seed)


def ring_poses(n: int = 12, radius: float = 10.0, height: float = 1.7,
               target_z: float = 2.5, phase_deg: float = 20.0):
    """``[(R, t), …]`` ``cam_from_world`` of ``n`` cameras evenly on a circle round the tower,
    looking at ``(0, 0, target_z)``; the first at ``phase_deg`` from the ``-y`` axis (so no
    camera looks squarely at a side)."""
    out = []
    for k in range(n):
        a = np.deg2rad(phase_deg + 360.0 * k / n)
        centre = np.array([radius * np.sin(a), -radius * np.cos(a), height])
        out.append(look_at(centre, [0.0, 0.0, target_z]))
    return out


def write_ring_folder(out: str | Path, n: int = 10, size: tuple[int, int] = (800, 600),
                      seed: int = 0, radius: float = 10.0, noise_sigma: float = 1.5,
                      sides: str = "ABCD") -> Path:
    """Render the ring and write ``cam00.png`` … and ``truth.npz`` into ``out`` (created).

    Returns
    -------
    out : Path — the photo folder (``truth.npz`` beside the images)
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    scene = build_tower_scene(seed, sides)
    K = intrinsics(size, hfov_deg=58.0)
    rng = np.random.default_rng([seed, 26])
    names, Rs, ts, depths = [], [], [], []
    for k, (R, t) in enumerate(ring_poses(n, radius)):
        image, depth = render_view(scene, K, R, t, size, rng=rng, noise_sigma=noise_sigma)
        name = f"cam{k:02d}.png"
        cv2.imwrite(str(out / name), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        names.append(name)
        Rs.append(R)
        ts.append(t)
        depths.append(depth)
    np.savez_compressed(out / "truth.npz", names=np.array(names), K=np.stack([K] * n),
                        R=np.stack(Rs), t=np.stack(ts), depth=np.stack(depths))
    return out
