"""Local features of each camera — the input of the local matching (Aragüés et al., Sec. V-B).

The paper extracts SURF features on each robot's image. SURF is patented and missing from the
pip builds of OpenCV, so SIFT is the default here; ORB and AKAZE are offered as fast binary
alternatives and SURF where the OpenCV build has the non-free algorithms. ``colmap-sift`` is
COLMAP's own SIFT (:func:`pipeline.colmap.sift.sift`: its DoG peak threshold, two orientations
per location, ``L1_ROOT`` descriptors), the default of the photographs (``run-images``), so that
a photo run starts from the features a COLMAP user gets.

One detail matters for the paper's counts: SIFT emits several keypoints at one location (one
per dominant orientation). With the strict one-feature-per-camera rule of Def. 2.4, such twins
would be reported as conflictive sets although they image the same point, so co-located
keypoints are merged here (the strongest response is kept).
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from pipeline.errors import InputError, die_with_parent
from pipeline.matching.methods import COLMAP_SIFT, FEATURE_METHODS, MAX_FEATURES, MIN_FEATURES
from pipeline.types import Features, View

__all__ = ["METHODS", "DETECTORS", "COLMAP_SIFT", "available_methods", "check_method", "extract", "extract_all",
           "merge_colocated", "surf_available", "root_sift", "photo_max_features",
           "PHOTO_CONTRAST_THRESHOLD", "MIN_FEATURES", "MAX_FEATURES"]

#: feature methods this module knows (:mod:`pipeline.matching.methods`, one detector each in
#: :data:`DETECTORS`); ``surf`` needs an OpenCV build with non-free algorithms
METHODS = FEATURE_METHODS

#: keypoints closer than this (pixels) count as one location (see :func:`merge_colocated`)
MERGE_RADIUS_PX = 0.5

#: images with a side shorter than this give zero features (smaller than any descriptor patch)
MIN_IMAGE_PX = 16

#: feature budget of a 640x480 image (the rendered formations), scaled with the image area by
#: :func:`photo_max_features`
BASE_FEATURES, BASE_AREA = 2000, 640 * 480
#: largest feature budget per image: COLMAP's ``SiftExtraction.max_num_features`` default
MAX_PHOTO_FEATURES = 8192
#: SIFT contrast threshold for photographs: OpenCV divides it by the 3 layers per octave, so
#: 0.02 is the DoG peak threshold of COLMAP's SIFT (``peak_threshold = 0.02 / 3``); OpenCV's own
#: default 0.04 keeps about half as many keypoints (6.3k vs 12.2k on a 1600x1200 photograph)
PHOTO_CONTRAST_THRESHOLD = 0.02


def photo_max_features(width: int, height: int, method: str = "sift") -> int:
    """Feature budget of one photograph: ``2000`` per 640x480 pixels, from 2000 to 8192;
    COLMAP's SIFT (``method="colmap-sift"``) keeps COLMAP's own 8192 at every size, as a
    COLMAP user gets (on the 800x640 Graffiti photographs the area rule's 3333 left 73 % of
    COLMAP's points).

    The density of the rendered 640x480 formations (2000 features), scaled with the image
    area, between 2000 and COLMAP's default 8192. A 1024x768 image gets 5120, a 1600x1200 one
    8192.

    Examples
    --------
    >>> photo_max_features(640, 480), photo_max_features(1024, 768), photo_max_features(1600, 1200)
    (2000, 5120, 8192)
    """
    if method == COLMAP_SIFT:
        return MAX_PHOTO_FEATURES
    area = max(int(width), 1) * max(int(height), 1)
    return int(np.clip(round(BASE_FEATURES * area / BASE_AREA), BASE_FEATURES, MAX_PHOTO_FEATURES))


def root_sift(descriptors: np.ndarray) -> np.ndarray:
    """RootSIFT (Arandjelović & Zisserman, CVPR 2012): L1-normalise, then square root.

    Euclidean distance between RootSIFT vectors is the Hellinger kernel between the original
    histograms, which matches SIFT better than L2 (COLMAP's default normalisation,
    ``L1_ROOT``). Rows come out unit-length in L2.

    Parameters
    ----------
    descriptors : ndarray, (N, D) float, non-negative

    Returns
    -------
    ndarray, (N, D) float32
    """
    d = np.asarray(descriptors, dtype=np.float32)
    norm = np.abs(d).sum(axis=1, keepdims=True)
    d = np.divide(d, norm, out=np.zeros_like(d), where=norm > 0)
    return np.sqrt(np.maximum(d, 0.0))


def available_methods() -> tuple[str, ...]:
    """The feature methods this OpenCV build offers (``surf`` only with non-free algorithms)."""
    return tuple(m for m in METHODS if m != "surf" or surf_available())


def surf_available() -> bool:
    """Whether this OpenCV build offers SURF (needs the non-free algorithms)."""
    try:
        cv2.xfeatures2d.SURF_create()
    except (cv2.error, AttributeError):
        return False
    return True


def check_method(method: str) -> None:
    """Raise :class:`InputError` now if ``method`` is unknown or unavailable in this build,
    so a command fails before its first stage rather than after rendering."""
    _detector(method, 2000)


def _sift(max_features: int, contrast_threshold: float | None):
    if contrast_threshold is not None:
        return cv2.SIFT_create(nfeatures=max_features, contrastThreshold=contrast_threshold)
    return cv2.SIFT_create(nfeatures=max_features)


def _surf(max_features: int, contrast_threshold: float | None):
    try:
        return cv2.xfeatures2d.SURF_create()
    except (cv2.error, AttributeError):
        raise InputError(
            "feature method 'surf' is not available: this OpenCV build has no non-free "
            "algorithms (OPENCV_ENABLE_NONFREE); use one of "
            f"{', '.join(available_methods())}") from None


#: the detector of each feature method, ``(max_features, contrast_threshold) -> detector``
#: (the contrast threshold is SIFT's; ``None`` for :data:`COLMAP_SIFT`, which is not OpenCV's:
#: :mod:`pipeline.colmap.sift` extracts it); AKAZE moved to contrib in OpenCV 5
#: (``cv2.AKAZE_create`` no longer exists) and takes no feature budget
DETECTORS = {
    "sift": _sift,
    "orb": lambda max_features, _: cv2.ORB_create(nfeatures=max_features),
    "akaze": lambda _n, _c: cv2.xfeatures2d.AKAZE_create(),
    "surf": _surf,
    COLMAP_SIFT: lambda _n, _c: None,
}
assert tuple(DETECTORS) == METHODS


def _detector(method: str, max_features: int, contrast_threshold: float | None = None):
    """The OpenCV detector for ``method`` (``None`` for :data:`COLMAP_SIFT`, which is not
    OpenCV's); raises :class:`InputError` for unknown/unavailable ones."""
    make = DETECTORS.get(method) if isinstance(method, str) else None
    if make is None:
        raise InputError(f"unknown feature method {method!r}; choose one of "
                         f"{', '.join(available_methods())}")
    return make(max_features, contrast_threshold)


def _gray(image_or_view) -> np.ndarray:
    """``(H, W)`` uint8 gray image from a View or an image array; InputError on anything else."""
    image = image_or_view.image if isinstance(image_or_view, View) else image_or_view
    if not isinstance(image, np.ndarray):
        raise InputError(f"expected an image array or a View, got {type(image).__name__}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (3, 4)):
        raise InputError(f"image of shape {image.shape} is not (H, W), (H, W, 3) or (H, W, 4)")
    if image.shape[0] < 1 or image.shape[1] < 1:
        raise InputError(f"image of shape {image.shape} is empty")
    if image.dtype != np.uint8:
        if image.dtype == bool:
            image = image.astype(np.uint8) * 255
        elif image.dtype == np.uint16:
            image = (image // 257).astype(np.uint8)  # 16-bit photographs
        elif np.issubdtype(image.dtype, np.floating):
            image = np.nan_to_num(image.astype(np.float64), nan=0.0, posinf=255.0, neginf=0.0)
            if image.max() <= 1.0:  # float images in [0, 1]
                image = image * 255.0 + 0.5
            image = np.clip(image, 0, 255).astype(np.uint8)
        elif np.issubdtype(image.dtype, np.integer):
            image = np.clip(image, 0, 255).astype(np.uint8)
        else:
            raise InputError(f"image dtype {image.dtype} is not a real number type (use uint8)")
    if image.ndim == 3:
        code = cv2.COLOR_RGB2GRAY if image.shape[2] == 3 else cv2.COLOR_RGBA2GRAY
        image = cv2.cvtColor(image, code)
    return np.ascontiguousarray(image)


def merge_colocated(keypoints: np.ndarray, response: np.ndarray,
                    radius: float = MERGE_RADIUS_PX) -> np.ndarray:
    """Indices of the keypoints to keep after merging co-located ones.

    Keypoints closer than ``radius`` pixels (transitively) form one group; of each group only
    the one with the strongest detector response is kept.

    Parameters
    ----------
    keypoints : ndarray, (N, 2) float
    response : ndarray, (N,) float
    radius : float
        Pixels.

    Returns
    -------
    keep : ndarray, (K,) int64, sorted ascending, ``K <= N``

    Notes
    -----
    ``O(N log N)``: neighbour pairs from a k-d tree, groups from
    ``scipy.sparse.csgraph.connected_components``.
    """
    n = int(keypoints.shape[0])
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(keypoints).query_pairs(radius, output_type="ndarray")
    if pairs.size == 0:
        return np.arange(n, dtype=np.int64)
    adj = coo_matrix((np.ones(len(pairs), dtype=bool), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, group = connected_components(adj, directed=False)
    # strongest first, then the first occurrence of each group is its strongest member
    order = np.lexsort((np.arange(n), -np.asarray(response, dtype=np.float64)))
    _, first = np.unique(group[order], return_index=True)
    return np.sort(order[first]).astype(np.int64)


def extract(image_or_view, method: str = "sift", max_features: int | None = 2000,
            merge_radius: float = MERGE_RADIUS_PX, *, contrast_threshold: float | None = None,
            rootsift: bool = False, budget_after_merge: bool = False) -> Features:
    """Detect and describe local features in one image.

    Parameters
    ----------
    image_or_view : View or ndarray, (H, W) / (H, W, 3) RGB / (H, W, 4) RGBA
        uint8 preferred; float images in ``[0, 1]`` are scaled to ``[0, 255]``, uint16 divided
        by 257, bool mapped to 0/255, other numbers clipped to ``[0, 255]``. Images with a side
        shorter than :data:`MIN_IMAGE_PX` give zero features.
    method : {"sift", "orb", "akaze", "surf", "colmap-sift"}
        ``surf`` only where OpenCV has non-free algorithms; ``colmap-sift`` is COLMAP's SIFT
        (``contrast_threshold``, ``rootsift`` and ``budget_after_merge`` do not apply: its
        descriptors are RootSIFT already and its budget counts locations).
    max_features : int or None
        Upper bound on the features returned (strongest kept). Co-located duplicates are merged
        after detection, so fewer may be returned. ``None``: :func:`photo_max_features` of the
        image's size.
    merge_radius : float
        Keypoints closer than this many pixels are one feature (strongest kept); ``0`` disables.
    contrast_threshold : float, optional
        SIFT only: OpenCV's ``contrastThreshold`` (default: OpenCV's, 0.04; photographs use
        :data:`PHOTO_CONTRAST_THRESHOLD`).
    rootsift : bool
        SIFT/SURF only: return RootSIFT descriptors (:func:`root_sift`).
    budget_after_merge : bool
        ``True``: detect without a budget, merge co-located keypoints, then keep the
        ``max_features`` strongest locations (the budget counts distinct points, as the
        photographs' defaults do). ``False``: the detector's own budget, then the merge, which
        leaves fewer (SIFT's extra orientations count against the budget; the formations'
        figures were measured so).

    Returns
    -------
    Features
        ``keypoints`` (N, 2) float32, ``descriptors`` (N, D) float32 (SIFT/SURF) or uint8
        (ORB/AKAZE), ``scales`` (N,) float32. A blank image gives ``N = 0`` with descriptors of
        shape ``(0, D)``.

    Raises
    ------
    InputError
        Unknown or unavailable ``method``, bad ``max_features``, or an array that is not an image.

    Examples
    --------
    >>> import numpy as np
    >>> len(extract(np.zeros((240, 320), np.uint8)))
    0
    """
    method = str(method).lower()
    if max_features is None:
        h, w = (image_or_view.image if isinstance(image_or_view, View)
                else np.asarray(image_or_view)).shape[:2]
        max_features = photo_max_features(w, h, method)
    if isinstance(max_features, bool) or not isinstance(max_features, (int, np.integer)) or max_features < 1:
        raise InputError(f"max_features must be a positive integer, got {max_features!r}")
    max_features = int(max_features)
    if method == COLMAP_SIFT:
        return _colmap_sift(_gray(image_or_view), max_features, merge_radius)
    detector = _detector(method, 0 if budget_after_merge and method == "sift" else max_features,
                         contrast_threshold if method == "sift" else None)
    gray = _gray(image_or_view)
    dim = int(detector.descriptorSize())
    dtype = np.uint8 if detector.descriptorType() == cv2.CV_8U else np.float32
    if min(gray.shape) < MIN_IMAGE_PX:  # no detector has room for a patch; ORB would raise
        kps, desc = (), None
    else:
        try:
            kps, desc = detector.detectAndCompute(gray, None)
        except cv2.error as exc:
            msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else "cv2.error"
            raise InputError(f"{method} failed on an image of shape {gray.shape}: {msg}") from None
    if desc is None or len(kps) == 0:  # blank image: OpenCV returns ((), None)
        return Features(np.zeros((0, 2), np.float32), np.zeros((0, dim), dtype),
                        np.zeros(0, np.float32), method)
    xy = cv2.KeyPoint_convert(kps).astype(np.float32).reshape(-1, 2)
    response = np.fromiter((k.response for k in kps), dtype=np.float64, count=len(kps))
    scales = np.fromiter((k.size for k in kps), dtype=np.float32, count=len(kps))
    keep = (merge_colocated(xy, response, merge_radius) if merge_radius > 0
            else np.arange(len(kps)))
    if len(keep) > max_features:  # AKAZE has no feature budget of its own (nor SIFT here
        # with budget_after_merge)
        strongest = np.argsort(-response[keep], kind="stable")[:max_features]
        keep = np.sort(keep[strongest])
    desc = desc[keep].astype(dtype, copy=False)
    if rootsift and dtype == np.float32:
        desc = root_sift(desc)
    return Features(np.ascontiguousarray(xy[keep]), np.ascontiguousarray(desc), scales[keep], method)


def _colmap_sift(gray: np.ndarray, max_features: int, merge_radius: float) -> Features:
    """COLMAP's SIFT (its budget: about the ``max_features`` largest-scale locations, each
    with up to two orientations; COLMAP drops whole scale levels, so more locations may stay,
    up to about twice the budget on small budgets: 236 for 200 on a 640x481 Sceaux
    photograph, 406 for 300 and 9–16 for 8 on small rendered views), co-located orientations
    merged as for
    OpenCV's (the largest scale kept, then the first)."""
    from pipeline.colmap.sift import sift

    if min(gray.shape) < MIN_IMAGE_PX:
        return Features(np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32),
                        np.zeros(0, np.float32), COLMAP_SIFT)
    got = sift(gray, max_features)
    # COLMAP's budget already counts locations: a second orientation is not cut here
    keep = (merge_colocated(got.keypoints, got.scales, merge_radius) if merge_radius > 0
            else np.arange(len(got.keypoints)))
    return Features(np.ascontiguousarray(got.keypoints[keep]),
                    np.ascontiguousarray(got.descriptors[keep]),
                    np.ascontiguousarray(got.scales[keep]), COLMAP_SIFT)


def extract_all(views, method: str = "sift", max_features: int | None = 2000,
                merge_radius: float = MERGE_RADIUS_PX, workers: int = 2, *,
                contrast_threshold: float | None = None, rootsift: bool = False,
                budget_after_merge: bool = False) -> list[Features]:
    """:func:`extract` for every camera, ``list[Features]`` in camera order.

    Parameters
    ----------
    views : sequence of View or image arrays, (n,)
    method, merge_radius, contrast_threshold, rootsift, budget_after_merge : see :func:`extract`
    max_features : int or None
        Per image; ``None``: :func:`photo_max_features` of each image's size and ``method``.
    workers : int
        Threads (OpenCV releases the GIL inside ``detectAndCompute``), or forked processes for
        COLMAP's SIFT (pycolmap holds it). ``1`` runs serially.
    """
    from pipeline.progress import progress

    views = list(views)
    _detector(str(method).lower(), 1)  # fail on a bad method before starting any thread

    def one(v):
        return extract(v, method, max_features, merge_radius,
                       contrast_threshold=contrast_threshold, rootsift=rootsift,
                       budget_after_merge=budget_after_merge)

    if workers <= 1 or len(views) <= 1:
        return [one(v) for v in progress(views, desc="features")]
    if str(method).lower() == COLMAP_SIFT and _FORK is not None:
        # pycolmap's SIFT holds the GIL (threads run it one at a time): forked workers, each
        # reading the views from the parent's memory as it was at the fork (copy-on-write)
        # and sending back its Features; the same calls in the same order per image, so the
        # same results as serially
        from pipeline.colmap.sift import sift_extractor

        # the extractors made once here, before the fork, are every worker's
        for v in views:
            h, w = (v.image if isinstance(v, View) else np.asarray(v)).shape[:2]
            sift_extractor(max_features or photo_max_features(w, h, method))
        global _FORKED_JOB
        _FORKED_JOB = (views, one)
        try:
            with ProcessPoolExecutor(max_workers=workers, mp_context=_FORK,
                                     initializer=die_with_parent,
                                     initargs=(os.getpid(),)) as pool:
                return list(progress(pool.map(_forked_one, range(len(views))),
                                     total=len(views), desc="features"))
        finally:
            _FORKED_JOB = None
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(progress(pool.map(one, views), total=len(views), desc="features"))


#: the job forked workers of :func:`extract_all` read (set just before the pool forks)
_FORKED_JOB = None
_FORK = multiprocessing.get_context("fork") if "fork" in multiprocessing.get_all_start_methods() \
    else None


def _forked_one(k: int) -> Features:
    views, one = _FORKED_JOB
    return one(views[k])
