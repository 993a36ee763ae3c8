"""Plain data records passed between the pipeline stages.

Conventions (DESIGN.md): camera ``i`` is robot ``i`` (0-based); feature ``r`` of camera ``i`` is
``(i, r)``; poses are ``cam_from_world`` (``x_cam = R @ x_world + t``); pixel coordinates follow
OpenCV (origin at the centre of the top-left pixel).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["View", "Features", "PairMatches", "Links"]


@dataclass
class View:
    """One camera's image and calibration.

    Attributes
    ----------
    name : str
        Image name (file name for real images, ``cam00`` … for rendered ones).
    image : ndarray, (H, W, 3) uint8 RGB or (H, W) uint8 gray
    K : ndarray, (3, 3) float64
        Pinhole intrinsics.
    R, t : ndarray, (3, 3) and (3,) float64
        ``cam_from_world`` pose; ``None`` for real images whose pose is unknown.
    depth : ndarray, (H, W) float32 or None
        Synthetic only: z-depth in the camera frame, ``inf`` where no surface was hit.
    intrinsics_known : bool
        ``False`` when K is a guess (matching then uses the fundamental matrix).
    intrinsics_source : str
        Where K came from for real images (``K.txt``, ``exif-35mm``, ``exif-focal-plane``,
        ``guess``); empty for rendered views.
    """

    name: str
    image: np.ndarray
    K: np.ndarray
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    depth: np.ndarray | None = None
    intrinsics_known: bool = True
    intrinsics_source: str = ""

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return int(self.image.shape[1]), int(self.image.shape[0])


@dataclass
class Features:
    """Local features of one camera.

    Attributes
    ----------
    keypoints : ndarray, (N, 2) float32, OpenCV pixel convention
    descriptors : ndarray, (N, D) float32 (SIFT) or uint8 (binary descriptors)
    scales : ndarray, (N,) float32 — keypoint size in pixels
    method : str — ``sift``, ``orb``, ``akaze`` or ``surf``
    """

    keypoints: np.ndarray
    descriptors: np.ndarray
    scales: np.ndarray
    method: str

    def __len__(self) -> int:
        return int(self.keypoints.shape[0])


@dataclass
class PairMatches:
    """The one-to-one association ``A_ij`` of one communication edge ``(i, j)``, ``i < j``.

    Attributes
    ----------
    i, j : int — cameras, ``i < j``
    pairs : ndarray, (M, 2) int32 — rows ``(r, s)``: feature ``r`` of ``i`` ↔ feature ``s`` of ``j``
    ratio : ndarray, (M,) float32 — Lowe ratio of the match (lower is better)
    epipolar_error : ndarray, (M,) float32 — Sampson error in pixels
    n_putative : int — matches after the ratio/mutual test, before RANSAC
    reason : str — empty when the association is usable, else why it is empty
    """

    i: int
    j: int
    pairs: np.ndarray
    ratio: np.ndarray
    epipolar_error: np.ndarray
    n_putative: int = 0
    reason: str = ""


@dataclass
class Links:
    """All links of the association graph, each undirected link stored once with ``cam_i < cam_j``.

    Attributes
    ----------
    cam_i, feat_i, cam_j, feat_j : ndarray, (L,) int64
    quality : ndarray, (L,) float64 — higher is better (used by the centralized quality merge)
    """

    cam_i: np.ndarray
    feat_i: np.ndarray
    cam_j: np.ndarray
    feat_j: np.ndarray
    quality: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        for name in ("cam_i", "feat_i", "cam_j", "feat_j"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=np.int64).reshape(-1))
        n = self.cam_i.shape[0]
        if not all(getattr(self, k).shape[0] == n for k in ("feat_i", "cam_j", "feat_j")):
            raise ValueError("Links: cam_i, feat_i, cam_j, feat_j must have the same length")
        if self.quality is None:
            self.quality = np.ones(n, dtype=np.float64)
        self.quality = np.asarray(self.quality, dtype=np.float64).reshape(-1)
        if self.quality.shape[0] != n:
            raise ValueError(f"Links: quality has length {self.quality.shape[0]}, expected {n}")

    def __len__(self) -> int:
        return int(self.cam_i.shape[0])

    def subset(self, mask: np.ndarray) -> Links:
        """The links where ``mask`` is true (boolean mask or index array)."""
        return Links(self.cam_i[mask], self.feat_i[mask], self.cam_j[mask], self.feat_j[mask],
                     self.quality[mask])

    @staticmethod
    def from_matches(matches: list[PairMatches]) -> Links:
        """Concatenate per-edge associations; quality is ``1 - ratio``."""
        parts = [m for m in matches if len(m.pairs)]
        if not parts:
            z = np.zeros(0, dtype=np.int64)
            return Links(z, z, z, z, np.zeros(0))
        return Links(
            np.concatenate([np.full(len(m.pairs), m.i) for m in parts]),
            np.concatenate([m.pairs[:, 0] for m in parts]),
            np.concatenate([np.full(len(m.pairs), m.j) for m in parts]),
            np.concatenate([m.pairs[:, 1] for m in parts]),
            np.concatenate([1.0 - m.ratio.astype(np.float64) for m in parts]),
        )


@dataclass
class RunRecord:
    """Everything a run produced, handed to ``viz`` (which only reads it) and to writers.

    Attributes
    ----------
    views : list[View]
    features : list[Features]
    links : Links — every link produced by matching, ``(L,)``
    status : ndarray, (L,) str — ``kept`` or ``deleted``
    reason : ndarray, (L,) str — stage that cut the link (``resolution``, ``fusion-outlier``…), ``''`` if kept
    round : ndarray, (L,) int — round of the stage in which the link was cut, ``-1`` if kept
    iteration : ndarray, (L,) int — detection/resolution iteration that cut it, ``-1`` otherwise
    conflictive_before : ndarray, (L,) bool — link lies in a conflictive set before resolution
    truth : ndarray, (L,) int8 — ``1`` good, ``0`` spurious, ``-1`` unknown (real images)
    points : ndarray, (P, 3) — triangulated track points after cleaning (world frame)
    point_tracks : ndarray, (P,) int — track id of each point
    gt_points : ndarray, (G, 3) or None — ground-truth points of the kept tracks (synthetic)
    fused_points : ndarray, (F, 3) or None — landmark estimates fused by dynamic voting
    report_markdown : str — the report table, for a text panel
    """

    views: list
    features: list
    links: Links
    status: np.ndarray
    reason: np.ndarray
    round: np.ndarray
    iteration: np.ndarray
    conflictive_before: np.ndarray
    truth: np.ndarray
    points: np.ndarray
    point_tracks: np.ndarray
    gt_points: np.ndarray | None = None
    fused_points: np.ndarray | None = None
    report_markdown: str = ""
