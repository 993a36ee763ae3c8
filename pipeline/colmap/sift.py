"""COLMAP's SIFT on the pipeline's images, and COLMAP's matching on given image pairs.

- :func:`sift` — ``pycolmap.Sift`` (COLMAP's CPU SIFT: DoG peak threshold ``0.02 / 3``, up to
  two orientations per location, ``L1_ROOT`` descriptors, its own feature budget counted in
  locations) on one gray image already in memory.
- :func:`match_pairs` — COLMAP's matcher and geometric verification (``match_image_pairs``:
  mutual nearest neighbours with the ratio test, then the two-view geometry of
  ``estimate_two_view_geometry``) on the pairs of a list only. The pipeline hands it the edges
  of the communication graph: a robot matches its neighbours and no one else (Aragüés et al.,
  Sec. II).

Interpretation: COLMAP matches inside a database; :func:`match_pairs` writes a private one (the
features of the images of the pairs, their cameras) in a temporary folder, runs the matcher
there and reads the verified matches back. The matcher of the Python API
(``pycolmap.FeatureMatcher.match``) was measured two orders of magnitude slower per pair than
the database path on the same descriptors (10 s against 0.08 s for two 10k-feature images, this
machine), so it is not used.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycolmap

from pipeline.colmap.base import COLMAP_PIXEL_OFFSET, quiet_colmap
from pipeline.errors import InputError
from pipeline.runfolder import scratch_folder

__all__ = ["SiftResult", "sift", "sift_extractor", "VerifiedPair", "match_pairs", "DESCRIPTOR_SCALE",
           "RADIAL_MODEL"]

#: COLMAP stores a unit-length SIFT descriptor as ``uint8`` values of ``512 * d`` (its
#: ``FeatureDescriptorsToUnsignedByte``); the pipeline keeps the float ``d = uint8 / 512``
DESCRIPTOR_SCALE = 512.0

#: camera model of photographs whose intrinsics are not a calibration: COLMAP's own default
RADIAL_MODEL = "SIMPLE_RADIAL"


@dataclass
class SiftResult:
    """Features of one image from COLMAP's SIFT.

    Attributes
    ----------
    keypoints : ndarray, (N, 2) float32 — OpenCV pixel convention
    scales : ndarray, (N,) float32 — keypoint scale (pixels)
    descriptors : ndarray, (N, 128) float32 — unit length, multiples of ``1 / 512``
    """

    keypoints: np.ndarray
    scales: np.ndarray
    descriptors: np.ndarray


@functools.lru_cache(maxsize=4)
def sift_extractor(max_features: int = 8192, threads: int = 1):
    """COLMAP's CPU SIFT extractor at COLMAP's default options but ``max_num_features``, made
    once per process and budget: making one costs about as much as an eighth of the
    extraction it then runs (Graffiti's six images: 2.42 s of CPU with a new extractor per
    image, 2.11 s with one; the same keypoints and descriptors). Made in a parent before
    :func:`pipeline.matching.features.extract_all` forks its workers, it is theirs too."""
    options = pycolmap.FeatureExtractionOptions()
    options.num_threads = int(threads)
    options.sift.max_num_features = int(max_features)
    with quiet_colmap(), warnings.catch_warnings():
        # pycolmap 4.2 marks Sift deprecated in favour of FeatureExtractor.create, whose
        # extract() returns Python objects per keypoint instead of arrays
        warnings.simplefilter("ignore", DeprecationWarning)
        return pycolmap.Sift(options, device=pycolmap.Device.cpu)


def sift(gray: np.ndarray, max_features: int = 8192, threads: int = 1) -> SiftResult:
    """COLMAP's CPU SIFT on one ``(H, W)`` uint8 image, at COLMAP's default options but
    ``max_num_features`` (:func:`sift_extractor`).

    COLMAP keeps about the ``max_features`` largest-scale locations (it drops whole scale
    levels, so more may stay, up to about twice a small budget); each may carry up to two
    orientations, so ``N`` may
    exceed ``max_features`` (merge co-located keypoints to count locations,
    :func:`pipeline.matching.features.merge_colocated`).
    """
    gray = np.ascontiguousarray(gray, dtype=np.uint8)
    if gray.ndim != 2:
        raise InputError(f"COLMAP SIFT needs a gray (H, W) image, got shape {gray.shape}")
    extractor = sift_extractor(int(max_features), int(threads))
    with quiet_colmap():
        kp, desc = extractor.extract(gray)
    kp = np.asarray(kp, dtype=np.float32).reshape(-1, 4)
    desc = np.asarray(desc, dtype=np.float32).reshape(-1, 128)
    return SiftResult(np.ascontiguousarray(kp[:, :2] - np.float32(COLMAP_PIXEL_OFFSET)),
                      np.ascontiguousarray(kp[:, 2]), np.ascontiguousarray(desc))


@dataclass
class VerifiedPair:
    """COLMAP's verified matches of one pair ``(i, j)``, ``i < j``.

    Attributes
    ----------
    i, j : int
    pairs : ndarray, (M, 2) int64 — inlier rows ``(r, s)``, feature ``r`` of ``i`` and ``s`` of ``j``
    n_putative : int — matches before geometric verification
    F : ndarray, (3, 3) float64 or None — ``x_jᵀ F x_i = 0`` in OpenCV pixels
    config : str — COLMAP's two-view configuration (``CALIBRATED``, ``UNCALIBRATED``,
        ``PLANAR_OR_PANORAMIC``, ``DEGENERATE`` …)
    """

    i: int
    j: int
    pairs: np.ndarray
    n_putative: int
    F: np.ndarray | None
    config: str


def _camera(K: np.ndarray, size: tuple[int, int], calibrated: bool,
            prior: bool) -> pycolmap.Camera:
    K = np.asarray(K, dtype=np.float64)
    w, h = size
    cx, cy = K[0, 2] + COLMAP_PIXEL_OFFSET, K[1, 2] + COLMAP_PIXEL_OFFSET
    if calibrated:
        cam = pycolmap.Camera(model="PINHOLE", width=w, height=h,
                              params=[K[0, 0], K[1, 1], cx, cy])
    else:
        cam = pycolmap.Camera(model=RADIAL_MODEL, width=w, height=h,
                              params=[float(np.sqrt(K[0, 0] * K[1, 1])), cx, cy, 0.0])
    cam.has_prior_focal_length = bool(prior)
    return cam


def _fundamental_px(tvg) -> np.ndarray | None:
    """``F`` of a two-view geometry in OpenCV pixels (COLMAP's is in its own convention)."""
    F = np.asarray(tvg.F, dtype=np.float64)
    if F.shape != (3, 3) or not np.isfinite(F).all() or not np.abs(F).sum() > 0:
        return None
    # x_colmap = x_cv + 0.5: F_cv = Tᵀ F T with T the shift by +0.5
    T = np.array([[1.0, 0.0, COLMAP_PIXEL_OFFSET], [0.0, 1.0, COLMAP_PIXEL_OFFSET], [0, 0, 1.0]])
    return T.T @ F @ T


def match_pairs(names: list[str], keypoints: list[np.ndarray], descriptors: list[np.ndarray],
                cameras: list[tuple[np.ndarray, tuple[int, int], bool, bool]], edges,
                threads: int = 1, ratio: float = 0.8, max_error_px: float = 4.0,
                min_inliers: int = 15) -> list[VerifiedPair]:
    """COLMAP's matching and geometric verification on the given pairs only.

    Parameters
    ----------
    names : list[str], (n,) — distinct image names
    keypoints : list of (m_k, 2) float — OpenCV pixel convention
    descriptors : list of (m_k, 128) float — unit-length SIFT (:data:`DESCRIPTOR_SCALE`)
    cameras : list of ``(K (3, 3), (width, height), calibrated, prior focal length)``; a
        calibrated camera is ``PINHOLE``, the others :data:`RADIAL_MODEL`
    edges : (E, 2) int — the pairs to match, ``i < j``
    threads : COLMAP threads (-1: all cores). One by default: on several threads COLMAP's CPU
        matching does not return the same matches from call to call (four Sceaux photographs,
        ring2, 40 calls on all cores of a 2-core machine: two different results; on one
        thread: one), and every later figure of a run follows its matches
    ratio, max_error_px, min_inliers : COLMAP's ``max_ratio``, the RANSAC ``max_error`` and
        ``min_num_inliers`` (its defaults: 0.8, 4 px, 15)

    Returns
    -------
    list[VerifiedPair], (E,) in the order of ``edges`` (no inliers where verification failed)
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    n = len(names)
    if not (len(keypoints) == len(descriptors) == len(cameras) == n):
        raise InputError(f"match_pairs: {n} names, {len(keypoints)} keypoint sets, "
                         f"{len(descriptors)} descriptor sets, {len(cameras)} cameras")
    out: list[VerifiedPair] = []
    with scratch_folder("colmap-match-") as tmp, quiet_colmap():
        db_path = Path(tmp) / "match.db"
        with pycolmap.Database.open(db_path) as db:
            ids = []
            for name, kp, d, (K, size, calibrated, prior) in zip(
                    names, keypoints, descriptors, cameras, strict=True):
                camera_id = db.write_camera(_camera(K, size, calibrated, prior))
                sensor = pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=camera_id)
                rig = pycolmap.Rig()
                rig.add_ref_sensor(sensor)
                rig_id = db.write_rig(rig)
                image_id = db.write_image(pycolmap.Image(name=name, camera_id=camera_id))
                frame = pycolmap.Frame()
                frame.rig_id = rig_id
                frame.add_data_id(pycolmap.data_t(sensor_id=sensor, id=image_id))
                db.write_frame(frame)
                db.write_keypoints(image_id, np.asarray(kp, dtype=np.float32).reshape(-1, 2)
                                   + np.float32(COLMAP_PIXEL_OFFSET))
                q = np.clip(np.rint(np.asarray(d, dtype=np.float32) * DESCRIPTOR_SCALE), 0, 255)
                db.write_descriptors(image_id, pycolmap.FeatureDescriptors(
                    pycolmap.FeatureExtractorType.SIFT, np.ascontiguousarray(q, dtype=np.uint8)))
                ids.append(image_id)
        pairs_file = Path(tmp) / "pairs.txt"
        pairs_file.write_text("".join(f"{names[i]} {names[j]}\n" for i, j in edges))
        matching = pycolmap.FeatureMatchingOptions()
        matching.num_threads = int(threads)
        matching.use_gpu = False
        matching.sift.max_ratio = float(ratio)
        pairing = pycolmap.ImportedPairingOptions()
        pairing.match_list_path = str(pairs_file)
        verification = pycolmap.TwoViewGeometryOptions()
        verification.ransac.max_error = float(max_error_px)
        verification.min_num_inliers = int(min_inliers)
        # a fixed RANSAC seed: the same images give the same matches
        verification.ransac.random_seed = 0
        pycolmap.match_image_pairs(db_path, matching_options=matching, pairing_options=pairing,
                                   verification_options=verification,
                                   device=pycolmap.Device.cpu)
        with pycolmap.Database.open(db_path) as db:
            for i, j in edges:
                a, b = ids[int(i)], ids[int(j)]
                raw = db.read_matches(a, b) if db.exists_matches(a, b) else np.zeros((0, 2))
                pairs = np.zeros((0, 2), dtype=np.int64)
                F, config = None, "UNDEFINED"
                if db.exists_two_view_geometry(a, b):
                    tvg = db.read_two_view_geometry(a, b)
                    pairs = np.asarray(tvg.inlier_matches, dtype=np.int64).reshape(-1, 2)
                    config = str(tvg.config).rsplit(".", 1)[-1]
                    F = _fundamental_px(tvg)
                out.append(VerifiedPair(int(i), int(j), pairs, int(len(raw)), F, config))
    return out
