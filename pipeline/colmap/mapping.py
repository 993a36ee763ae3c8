"""COLMAP incremental mapping and what the pipeline reads from a reconstruction.

- :func:`incremental_mapping` — ``pycolmap.incremental_mapping`` and its figures (registered
  images, points, mean track length, mean reprojection error).
- :func:`incremental_mapping_with_retry` — the same, once more with a relaxed registration
  threshold when COLMAP's leaves images out.
- :func:`mapping_from_poses` — the tracks of a database triangulated on the poses of an
  earlier reconstruction of the same images, bundle adjusted, the images it lacks registered.
- :func:`registered_poses`, :func:`similarity_between` — poses and gauge of a reconstruction.
- :func:`write_model`, :func:`read_model` — a reconstruction as a COLMAP model folder.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from pipeline.colmap.base import COLMAP_PIXEL_OFFSET, quiet_colmap, write_reconstruction
from pipeline.colmap.database import check_database_file
from pipeline.errors import InputError
from pipeline.runfolder import scratch_folder

__all__ = ["MappingSummary", "incremental_mapping", "incremental_mapping_with_retry",
           "mapping_from_poses", "poses_usable", "COLMAP_MIN_POSE_INLIERS", "RETRY_MIN_POSE_INLIERS",
           "write_model",
           "read_model", "model_images", "model_points", "model_tracks", "registered_poses",
           "undistorted_keypoints",
           "similarity_between"]


#: COLMAP's ``abs_pose_min_num_inliers``: 2D-3D matches an image needs before its pose is tried
COLMAP_MIN_POSE_INLIERS = 30
#: the relaxed threshold of :func:`incremental_mapping_with_retry`: COLMAP's own
#: ``min_num_inliers`` of two-view verification (the matches it trusts for a pair's geometry)
RETRY_MIN_POSE_INLIERS = 15


@dataclass
class MappingSummary:
    """Figures of an incremental reconstruction (the largest model when there are several).

    Attributes
    ----------
    images : int — images in the database
    models : int — reconstructions COLMAP produced
    registered_images : int — images registered in the largest model
    registered_names : list[str]
    points : int — 3D points of the largest model
    observations : int — 2D observations of those points
    mean_track_length : float — observations per point (0.0 without a point)
    mean_reprojection_error : float — pixels (0.0 without a point)
    reconstruction : pycolmap.Reconstruction or None
    min_pose_inliers : int — the mapper's ``abs_pose_min_num_inliers`` for this model
    registered_at_colmap_default : int or None — images COLMAP's default threshold registered,
        when :func:`incremental_mapping_with_retry` kept a model of the relaxed one
    other_models : list of list[str] — the registered images of each other model COLMAP made
        (largest first); they are not in this summary's model, nor in ``sparse/``
    """

    images: int
    models: int
    registered_images: int
    registered_names: list[str]
    points: int
    observations: int
    mean_track_length: float
    mean_reprojection_error: float
    reconstruction: object = None
    min_pose_inliers: int = COLMAP_MIN_POSE_INLIERS
    registered_at_colmap_default: int | None = None
    other_models: list = field(default_factory=list)

    def summary(self) -> dict:
        """The figures as a JSON-ready dict (without the reconstruction); the means are
        ``None`` without a point (a model of no point has no error to average, not a 0 px one)."""
        def mean(value) -> float | None:
            return round(float(value), 4) if self.points else None

        out = {"images": self.images, "models": self.models,
               "registered_images": self.registered_images,
               "registered_names": list(self.registered_names), "points": self.points,
               "observations": self.observations,
               "mean_track_length": mean(self.mean_track_length),
               "mean_reprojection_error": mean(self.mean_reprojection_error),
               "min_pose_inliers": int(self.min_pose_inliers)}
        if self.registered_at_colmap_default is not None:
            out["registered_at_colmap_default"] = int(self.registered_at_colmap_default)
        if self.other_models:  # said only when COLMAP made several models
            out["other_models"] = [list(names) for names in self.other_models]
        bogus = bogus_camera_images(self.reconstruction)
        if bogus:  # said only when there are some
            out["bogus_camera_images"] = bogus
        return out


def _pipeline_options(database_path: Path, num_threads: int, seed: int, fixed_intrinsics,
                      image_dir, min_pose_inliers: int = COLMAP_MIN_POSE_INLIERS) -> tuple:
    """COLMAP's mapping options for a database: ``(options, images in the database, ids of
    the cameras held constant)``; every camera calibrated: no focal length refined (the
    radial term still is); some: those cameras held constant."""
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = num_threads
    options.random_seed = seed
    options.mapper.abs_pose_min_num_inliers = int(min_pose_inliers)
    options.extract_colors = bool(image_dir)
    with quiet_colmap(), pycolmap.Database.open(database_path) as db:
        images = db.read_all_images()
    fixed = set(fixed_intrinsics)
    constant = set()
    if images and all(im.name in fixed for im in images):
        options.ba_refine_focal_length = False
    else:
        constant = {im.camera_id for im in images if im.name in fixed}
        options.constant_cameras = constant
    return options, images, constant


def _summary(rec, n_images: int, n_models: int,
             min_pose_inliers: int = COLMAP_MIN_POSE_INLIERS) -> MappingSummary:
    """The figures of ``rec`` (the largest model; zeros when it is None)."""
    if rec is None:
        return MappingSummary(n_images, 0, 0, [], 0, 0, 0.0, 0.0, None, min_pose_inliers)
    rec.update_point_3d_errors()
    names = sorted(rec.images[i].name for i in rec.reg_image_ids())
    return MappingSummary(
        images=n_images, models=n_models, registered_images=rec.num_reg_images(),
        registered_names=names, points=rec.num_points3D(),
        observations=int(rec.compute_num_observations()),
        mean_track_length=float(rec.compute_mean_track_length()) if rec.num_points3D() else 0.0,
        mean_reprojection_error=float(rec.compute_mean_reprojection_error()),
        reconstruction=rec, min_pose_inliers=int(min_pose_inliers))


def _largest(models: dict):
    return max(models.values(), key=lambda r: (r.num_reg_images(), r.num_points3D())) \
        if models else None


def _others(models: dict, kept) -> list[list[str]]:
    """The registered image names of every model but ``kept``, largest first."""
    out = [sorted(r.images[i].name for i in r.reg_image_ids())
           for r in models.values() if r is not kept]
    return sorted((names for names in out if names), key=lambda names: (-len(names), names))


def incremental_mapping(database_path: str | Path, *, image_dir: str | Path = "",
                        output_dir: str | Path | None = None, num_threads: int = -1,
                        seed: int = 0, fixed_intrinsics=(),
                        min_pose_inliers: int = COLMAP_MIN_POSE_INLIERS,
                        ignore_watermarks: bool = False) -> MappingSummary:
    """``pycolmap.incremental_mapping`` on a database; figures of the largest model.

    Parameters
    ----------
    database_path : database with two-view geometries (e.g. from :func:`write_database`)
    image_dir : folder of the images, only to colour points; ``""`` skips colours (the
        pipeline maps downscaled images whose files do not exist at that size)
    output_dir : where COLMAP writes its models; a temporary folder when None
    num_threads : COLMAP threads (-1: all cores)
    seed : COLMAP's random seed, for repeatable figures
    fixed_intrinsics : iterable of image names whose calibration the bundle adjustments keep
        (with few views COLMAP otherwise lets the focal length drift far from a known
        calibration at no cost in reprojection error): when it names every image, no focal
        length is refined and the distortion terms still are; otherwise those cameras are
        held constant
    min_pose_inliers : the mapper's ``abs_pose_min_num_inliers`` (COLMAP's default 30)
    ignore_watermarks : the mapper's ``ignore_watermarks`` (COLMAP's default off: its
        ``WATERMARK`` pairs are used like the others)

    Returns
    -------
    MappingSummary — zeros when no model could be initialised
    """
    database_path = Path(database_path)
    check_database_file(database_path)
    options, images, _ = _pipeline_options(database_path, num_threads, seed, fixed_intrinsics,
                                           image_dir, min_pose_inliers)
    options.ignore_watermarks = bool(ignore_watermarks)
    with scratch_folder("colmap-map-") as tmp:
        out = Path(output_dir) if output_dir is not None else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        models = _mapping(database_path, str(image_dir or tmp), out, options, len(images))
    largest = _largest(models)
    out = _summary(largest, len(images), len(models), min_pose_inliers)
    out.other_models = _others(models, largest)
    return out


def incremental_mapping_with_retry(database_path: str | Path, *, mapping=None,
                                   **options) -> MappingSummary:
    """:func:`incremental_mapping` at COLMAP's registration threshold and, when that leaves
    images of the database out, once more at :data:`RETRY_MIN_POSE_INLIERS`; the model that
    registers more images is kept (the first on a tie), and the summary says which threshold
    made it (``min_pose_inliers``) and what the default registered.

    Why: COLMAP tries an image's pose only once it sees ``abs_pose_min_num_inliers`` = 30
    triangulated points. Its SIFT gives up to two orientations at one location, each a
    keypoint (about one keypoint in six on the rendered ring of :mod:`data_synth.symmetric`),
    so part of those 30 are the same points twice; the pipeline's features keep one
    orientation per location (``merge_radius``: one feature per point, the association's
    model), and where the view graph is weak an image may see fewer than 30 points although
    its pose is well determined. Measured on that ring (ABCD, 18 cameras 20° apart, the
    database of ``run-images --graph complete --no-fusion``): render seed 2 registered 6 of
    18 images at 30 and 18 at 15, median rotation error 0.67° and 0.25° against the truth;
    seed 3, 5 and 18, 0.06° and 0.11° (COLMAP's own pipeline on the same photographs: 6 of
    18, and 18 folded half a turn); seeds 0, 1 and 4 register 18 at 30, so nothing is
    retried. The relaxed value is COLMAP's own ``min_num_inliers`` of two-view verification,
    the number of matches it trusts to fix a pair's geometry. A lower threshold also lets
    an image register on fewer, possibly wrong, matches (a symmetric scene may fold either
    way): the retry runs only when images are missing, and the report names the threshold.

    ``mapping`` (tests): the function that maps at a threshold, :func:`incremental_mapping`
    by default; ``options`` go to it.
    """
    mapping = mapping or incremental_mapping
    first = mapping(database_path, min_pose_inliers=COLMAP_MIN_POSE_INLIERS, **options)
    if first.registered_images >= first.images:
        return first
    retry = mapping(database_path, min_pose_inliers=RETRY_MIN_POSE_INLIERS, **options)
    if retry.registered_images <= first.registered_images:
        return first
    retry.registered_at_colmap_default = first.registered_images
    return retry


def _mapping(database_path: Path, image_dir: str, out: Path, options, n_images: int,
             input_path: str | Path = "") -> dict:
    """``pycolmap.incremental_mapping``, quiet, with a progress bar of the images registered."""
    # COLMAP insists on an existing image folder even when it reads no pixels
    from pipeline.progress import progress

    # its errors too ("Failed to create any sparse model"): what the mapping failed to do is
    # the caller's to say (a run's flags name it and its likely cause), not a raw log line
    with quiet_colmap(3), progress(None, total=n_images,
                                   desc="mapping (images registered)") as bar, \
            interrupts_kept():
        return pycolmap.incremental_mapping(
            database_path, image_dir, out, options, input_path=str(input_path),
            initial_image_pair_callback=lambda: bar.update(2),
            next_image_callback=lambda: bar.update(1))


@contextmanager
def interrupts_kept():
    """Re-raise a Ctrl-C (or a SIGTERM the program handles) that a call into COLMAP swallowed.

    ``pycolmap.incremental_mapping`` checks for interrupts and runs Python callbacks (the
    progress bar); a KeyboardInterrupt raised there can end the mapping early with the
    reconstruction kept and the call returning normally, so the command went on and wrote a
    result from a cut-short mapping (seen under load: ``clean-db --fusion`` exited 0 after a
    Ctrl-C, 787 points where the full run has 786). In the main thread the SIGINT handler is
    wrapped for the call: it records the signal (and acts as before); if one arrived, a
    KeyboardInterrupt is raised once the call has returned. So are the SIGTERM and SIGHUP
    handlers set in Python (the command line's, :func:`pipeline.errors.clean_up_on_terminate`):
    their :class:`~pipeline.errors.Terminated` is raised once the call has returned."""
    if threading.current_thread() is not threading.main_thread():
        yield  # signals reach the main thread only
        return
    got = []
    previous = {sig: signal.getsignal(sig)
                for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}

    def handler(signum, frame):
        got.append(signum)
        if callable(previous[signum]):
            previous[signum](signum, frame)
        elif previous[signum] != signal.SIG_IGN:
            raise KeyboardInterrupt

    # SIGINT always; SIGTERM and SIGHUP where Python handles them (their default action
    # stays: it ends the process at once)
    wrapped = [sig for sig, old in previous.items() if sig == signal.SIGINT or callable(old)]
    for sig in wrapped:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig in wrapped:
            signal.signal(sig, previous[sig])
    if signal.SIGINT in got:
        raise KeyboardInterrupt
    if got:
        from pipeline.errors import Terminated

        raise Terminated(got[0])


#: bundle adjustment rounds of :func:`mapping_from_poses` (each followed by the mapper's
#: filter); COLMAP's own global refinement stops at the same change of observations
MAX_REFINEMENTS = 5
MIN_REFINEMENT_CHANGE = 0.0005


def mapping_from_poses(database_path: str | Path, reconstruction, *, num_threads: int = -1,
                       seed: int = 0, fixed_intrinsics=(),
                       min_pose_inliers: int = COLMAP_MIN_POSE_INLIERS) -> MappingSummary:
    """The verified matches of ``database_path`` mapped on the poses of ``reconstruction``.

    Steps: the tracks of the database's two-view geometries triangulated on the registered
    poses and cameras of ``reconstruction`` (its points are dropped:
    ``pycolmap.triangulate_points``, COLMAP's point triangulator, which completes, merges and
    filters the tracks with the poses held); then global bundle adjustments with poses,
    points and the cameras not named in ``fixed_intrinsics`` refined, each followed by
    COLMAP's mapper filter (reprojection error above ``filter_max_reproj_error``, 4 px, or
    triangulation angle below ``filter_min_tri_angle``, 1.5°), until fewer than
    :data:`MIN_REFINEMENT_CHANGE` of the observations change (at most
    :data:`MAX_REFINEMENTS`, COLMAP's ``ba_global_max_refinements``); last, images of the
    database that ``reconstruction`` did not register are offered to COLMAP's incremental
    mapper, continuing this model (its 2D-3D registration, then its structure-less
    fallback).

    Why (``pipeline.runs.images``, the reconstruction after cleaning): the cleaned links
    are a subset of links whose reconstruction is known, and fusion judged them with its
    poses. Mapping them from scratch makes COLMAP find every pose again from that subset,
    and where the view graph is weak the correct matches alone may not reach its
    registration thresholds (``abs_pose_min_num_inliers`` = 30 2D-3D matches seen before
    an image is even tried, twice that many 2D-2D for the structure-less fallback). On the
    rendered ring of :mod:`data_synth.symmetric` (ABCD, 18 cameras 20° apart) the frontier
    image saw 38 triangulated points in the mapping of all links (too few inliers: the
    structure-less fallback registered it); against the 5-image model of the cleaned links
    it saw 24 (30 with all links), fusion having cut 39 of its links to those images, 34 of
    them wrong by the truth, so it was never tried and the mapper stopped at 5 of 18;
    removing exactly the links the truth calls wrong stopped it at 5 too (mapping seeds 0,
    1 and 2). On the same poses the kept links
    give 18 of 18 images and, refined, lower pose errors than the reconstruction before
    cleaning (``bench/images_vs_colmap.py``).

    What it cannot do: re-decide a pose. A reconstruction folded by wrong matches stays
    folded (its bundle adjustment only refines); :func:`incremental_mapping` on the same
    database is the from-scratch alternative (``run-images --remap``).

    Parameters
    ----------
    database_path : a database whose image ids, names and keypoints are those
        ``reconstruction`` was mapped from (e.g. two :func:`write_database` files of the same
        views and features, with different kept links)
    reconstruction : pycolmap.Reconstruction — not modified (a copy is refined); ``None``, or
        not :func:`poses_usable`: :func:`incremental_mapping` from scratch
    num_threads, seed, fixed_intrinsics, min_pose_inliers : as :func:`incremental_mapping`
        (the images it lacks are registered at ``min_pose_inliers``: pass the threshold that
        made ``reconstruction``)

    Returns
    -------
    MappingSummary — ``models`` is 1 (the continued model)

    Raises
    ------
    InputError
        The database does not hold ``reconstruction``'s images under the same ids and names.
    """
    database_path = Path(database_path)
    check_database_file(database_path)
    if not poses_usable(reconstruction):
        return incremental_mapping(database_path, num_threads=num_threads, seed=seed,
                                   fixed_intrinsics=fixed_intrinsics,
                                   min_pose_inliers=min_pose_inliers)
    options, images, constant = _pipeline_options(database_path, num_threads, seed,
                                                  fixed_intrinsics, "", min_pose_inliers)
    names = {int(im.image_id): im.name for im in images}
    for image_id, image in reconstruction.images.items():
        if names.get(int(image_id)) != image.name:
            raise InputError(
                f"database {str(database_path)!r} does not hold the reconstruction's image "
                f"{image.name!r} under id {image_id} (it has "
                f"{names.get(int(image_id))!r}): map the database it was made from")
    with scratch_folder("colmap-poses-") as tmp, quiet_colmap():
        tmp = Path(tmp)
        rec = pycolmap.triangulate_points(pycolmap.Reconstruction(reconstruction),
                                          database_path, tmp, tmp / "triangulated",
                                          clear_points=True, options=options)
        _refine(rec, options, constant)
        if rec.num_reg_images() < len(images):
            start = tmp / "start"
            start.mkdir()
            rec.write(start)
            options.multiple_models = False
            models = _mapping(database_path, str(tmp), tmp / "continued", options,
                              len(images), input_path=start)
            rec = _largest(models) or rec
    return _summary(rec, len(images), 1, min_pose_inliers)


def poses_usable(reconstruction) -> bool:
    """Whether :func:`mapping_from_poses` can start from ``reconstruction``: two registered
    images or more, and no camera of a registered image with parameters COLMAP's mapper
    deems bogus (focal length ratio outside ``[0.1, 10]`` or a distortion term above 1, its
    ``min_focal_length_ratio``, ``max_focal_length_ratio``, ``max_extra_param``): its
    triangulator skips such images, so a start with one would give no points (seen on the
    AABB ring with ``knn:4``: a shared camera left at ``k = -1.07``)."""
    if reconstruction is None or reconstruction.num_reg_images() < 2:
        return False
    return not bogus_camera_images(reconstruction)


def bogus_camera_images(reconstruction) -> list[str]:
    """Names of the registered images whose camera has parameters COLMAP's mapper deems bogus
    (:func:`poses_usable`: focal length ratio outside ``[0.1, 10]`` or a distortion term
    above 1), sorted; empty without a reconstruction."""
    if reconstruction is None:
        return []
    mapper = pycolmap.IncrementalMapperOptions()
    out = []
    for i in reconstruction.reg_image_ids():
        image = reconstruction.images[i]
        if reconstruction.cameras[image.camera_id].has_bogus_params(
                mapper.min_focal_length_ratio, mapper.max_focal_length_ratio,
                mapper.max_extra_param):
            out.append(image.name)
    return sorted(out)


def _refine(rec, options, constant_cameras) -> None:
    """Global bundle adjustment (poses, points, the cameras not held constant) and COLMAP's
    mapper filter, repeated until the observations settle (:func:`mapping_from_poses`)."""
    ba = options.get_global_bundle_adjustment()
    mapper = options.get_mapper()
    config = pycolmap.BundleAdjustmentConfig()
    for image_id in rec.reg_image_ids():
        config.add_image(image_id)
    for camera_id in constant_cameras:
        if camera_id in rec.cameras:
            config.set_constant_cam_intrinsics(camera_id)
    config.fix_gauge(pycolmap.BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD)
    for _ in range(MAX_REFINEMENTS):
        observations = max(int(rec.compute_num_observations()), 1)
        pycolmap.create_default_bundle_adjuster(ba, config, rec).solve()
        filtered = pycolmap.ObservationManager(rec).filter_all_points3D(
            mapper.filter_max_reproj_error, mapper.filter_min_tri_angle)
        if filtered / observations < MIN_REFINEMENT_CHANGE:
            break


def write_model(path: str | Path, reconstruction=None) -> Path:
    """Write ``reconstruction`` (an empty one when ``None``) as a COLMAP model folder that
    loads back with :func:`read_model`; the folder is created."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    write_reconstruction(reconstruction if reconstruction is not None else pycolmap.Reconstruction(),
                         path)
    return path


def rescale_to_files(rec, sizes: dict[str, tuple[int, int]]) -> None:
    """Scale a reconstruction made on downscaled images back to the image files, in place.

    Parameters
    ----------
    rec : pycolmap.Reconstruction — cameras and 2D points at the size that was mapped
    sizes : ``{image name: (width, height)}`` of the files the images were loaded from

    Notes
    -----
    In COLMAP's pixel convention (origin at the top-left *corner*) resizing an image by
    ``(sx, sy)`` multiplies every pixel coordinate by ``(sx, sy)``: ``Camera.rescale`` scales
    focal lengths and principal point, each 2D point is scaled likewise. A camera shared by
    several images is rescaled once. Poses and 3D points do not change.
    """
    factor: dict[int, tuple[float, float]] = {}
    for image in rec.images.values():
        if image.name not in sizes:
            continue
        W, H = (int(v) for v in sizes[image.name])
        if image.camera_id not in factor:
            cam = rec.cameras[image.camera_id]
            factor[image.camera_id] = (W / cam.width, H / cam.height)
            if (W, H) != (cam.width, cam.height):
                cam.rescale(W, H)
        sx, sy = factor[image.camera_id]
        if (sx, sy) == (1.0, 1.0):
            continue
        for p in image.points2D:
            xy = p.xy
            p.xy = np.array([xy[0] * sx, xy[1] * sy])


def write_model_for_files(path: str | Path, reconstruction, sizes: dict[str, tuple[int, int]],
                          image_dir: str | Path) -> Path:
    """Write ``reconstruction`` as a model folder at the resolution of its image files.

    A copy is scaled (:func:`rescale_to_files`) and its points take their colours from the
    files in ``image_dir``; ``reconstruction`` itself is left at the size it was mapped at.
    """
    path = write_model(path, reconstruction)
    if reconstruction is None:
        return path
    full = pycolmap.Reconstruction(str(path))
    rescale_to_files(full, sizes)
    _extract_colors(full, image_dir)
    write_reconstruction(full, path)
    return path


def _extract_colors(rec, image_dir: str | Path) -> None:
    """Colour each point of ``rec`` in place with the mean of the file's pixel (bilinear, at
    ``xy - 0.5``: COLMAP's pixel centres) over its observations in the registered images, as
    ``Reconstruction.extract_colors_for_all_images`` does, but with the files decoded as
    run-images decodes them (:func:`pipeline.inputs.photos.load_image`): COLMAP's own reader
    cannot read WebP and left every point of a WebP folder black. A point seen by no readable
    pixel is black."""
    from pipeline.inputs.photos import load_image

    sums: dict[int, np.ndarray] = {}
    counts: dict[int, int] = {}
    for image_id in rec.reg_image_ids():
        image = rec.images[image_id]
        observed = [(p.point3D_id, p.xy) for p in image.points2D if p.has_point3D()]
        if not observed:
            continue
        pixels, _ = load_image(Path(image_dir) / image.name)
        h, w = pixels.shape[:2]
        xy = np.array([q for _, q in observed], dtype=np.float64) - COLMAP_PIXEL_OFFSET
        inside = (xy[:, 0] >= 0) & (xy[:, 1] >= 0) & (xy[:, 0] <= w - 1) & (xy[:, 1] <= h - 1)
        colours = _bilinear(pixels, np.clip(xy, 0, [w - 1, h - 1]))
        for (pid, _), colour, ok in zip(observed, colours, inside, strict=True):
            if ok:
                sums[pid] = sums.get(pid, 0.0) + colour
                counts[pid] = counts.get(pid, 0) + 1
    for pid, point in rec.points3D.items():
        colour = sums[pid] / counts[pid] if pid in counts else np.zeros(3)
        point.color = np.clip(np.rint(colour), 0, 255).astype(np.uint8)


def _bilinear(pixels: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(N, 3) float64: ``pixels`` (H, W, 3) RGB or (H, W) gray interpolated at the N points
    ``xy`` (inside the image); only the pixels sampled are converted, not the image."""
    h, w = pixels.shape[:2]
    x0 = np.floor(xy[:, 0]).astype(np.int64)
    y0 = np.floor(xy[:, 1]).astype(np.int64)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    dx, dy = (xy[:, 0] - x0)[:, None], (xy[:, 1] - y0)[:, None]

    def px(y, x):
        v = pixels[y, x].astype(np.float64)
        return v if v.ndim == 2 else v[:, None]

    out = ((1 - dx) * (1 - dy) * px(y0, x0) + dx * (1 - dy) * px(y0, x1)
           + (1 - dx) * dy * px(y1, x0) + dx * dy * px(y1, x1))
    return np.broadcast_to(out, (len(xy), 3))


def read_model(path: str | Path):
    """The ``pycolmap.Reconstruction`` of a COLMAP model folder (e.g. a run's ``sparse/``)."""
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"COLMAP model {str(path)!r}: no such folder")
    return pycolmap.Reconstruction(str(path))


def model_images(rec) -> dict[str, dict]:
    """Every image of a reconstruction by name: ``image_id``, ``size`` ``(w, h)``, ``K``
    (3, 3) and ``keypoints`` (N, 2) in the OpenCV pixel convention, and ``R`` (3, 3), ``t``
    (3,) ``cam_from_world`` where the image is registered (else ``None``)."""
    out = {}
    if rec is None:
        return out
    registered = set(rec.reg_image_ids())
    for image_id, image in rec.images.items():
        cam = rec.cameras[image.camera_id]
        K = np.array(cam.calibration_matrix(), dtype=np.float64)
        K[:2, 2] -= COLMAP_PIXEL_OFFSET
        kp = np.array([p.xy for p in image.points2D], dtype=np.float64).reshape(-1, 2)
        R = t = None
        if image_id in registered:
            pose = image.cam_from_world()
            R = np.asarray(pose.rotation.matrix(), dtype=np.float64)
            t = np.asarray(pose.translation, dtype=np.float64).reshape(3)
        out[image.name] = {"image_id": int(image_id), "size": (int(cam.width), int(cam.height)),
                           "K": K, "keypoints": kp - COLMAP_PIXEL_OFFSET, "R": R, "t": t}
    return out


def model_points(rec) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray]:
    """The 3D points of a reconstruction, in its own order.

    Returns
    -------
    xyz : (P, 3) float64
    point_ids : (P,) int64
    first_image : list of P str — name of the image of each point's first observation
    first_keypoint : (P,) int64 — index of that observation's keypoint in its image
    """
    if rec is None or rec.num_points3D() == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64), [], np.zeros(0, dtype=np.int64)
    xyz, ids, names, kp = [], [], [], []
    for point_id, p in rec.points3D.items():
        el = p.track.elements[0]
        xyz.append(p.xyz)
        ids.append(point_id)
        names.append(rec.images[el.image_id].name)
        kp.append(el.point2D_idx)
    return (np.asarray(xyz, dtype=np.float64).reshape(-1, 3), np.asarray(ids, dtype=np.int64),
            names, np.asarray(kp, dtype=np.int64))


def model_tracks(rec) -> list[list[tuple[str, float, float]]]:
    """Every 3D point's track: its observations ``(image name, x, y)`` in COLMAP's pixel
    convention, in the reconstruction's point order."""
    if rec is None:
        return []
    names = {i: im.name for i, im in rec.images.items()}
    out = []
    for p in rec.points3D.values():
        track = []
        for el in p.track.elements:
            xy = rec.images[el.image_id].points2D[el.point2D_idx].xy
            track.append((names[el.image_id], float(xy[0]), float(xy[1])))
        out.append(track)
    return out


def undistorted_keypoints(rec, name: str, xy: np.ndarray) -> np.ndarray:
    """Keypoints ``(m, 2)`` (OpenCV convention) of image ``name`` with its camera's lens
    distortion removed: where a pinhole with the camera's own ``K``
    (:func:`registered_poses`) would have seen them. Unchanged for a camera without distortion
    or an image not in ``rec``."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    image = next((im for im in rec.images.values() if im.name == name), None) \
        if rec is not None else None
    if image is None or len(xy) == 0:
        return xy.copy()
    cam = rec.cameras[image.camera_id]
    rays = np.asarray(cam.cam_from_img(xy + COLMAP_PIXEL_OFFSET), dtype=np.float64)
    K = np.asarray(cam.calibration_matrix(), dtype=np.float64)
    out = rays @ K[:2, :2].T + K[:2, 2]
    bad = ~np.isfinite(out).all(axis=1)
    out[bad] = xy[bad] + COLMAP_PIXEL_OFFSET
    return out - COLMAP_PIXEL_OFFSET


def registered_poses(rec) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``{image name: (R (3, 3), t (3,), K (3, 3))}`` of the registered images of ``rec``.

    ``R, t`` is ``cam_from_world``; ``K`` is the (possibly refined) camera in the OpenCV pixel
    convention.
    """
    out = {}
    if rec is None:
        return out
    for image_id in rec.reg_image_ids():
        image = rec.images[image_id]
        pose = image.cam_from_world()
        K = np.array(rec.cameras[image.camera_id].calibration_matrix(), dtype=np.float64)
        K[:2, 2] -= COLMAP_PIXEL_OFFSET
        out[image.name] = (np.asarray(pose.rotation.matrix(), dtype=np.float64),
                           np.asarray(pose.translation, dtype=np.float64).reshape(3), K)
    return out


def similarity_between(src, tgt) -> np.ndarray | None:
    """``tgt_from_src`` similarity ``(3, 4)`` (``x_tgt = M[:, :3] @ x_src + M[:, 3]``) from the
    projection centres of the images registered in both reconstructions (by name), or None
    with fewer than three such images. Two reconstructions of one scene have different gauges;
    this puts points of one into the frame of the other; None too when the centres are
    collinear (the rotation about their line is unknown).

    Umeyama's closed form by OpenCV (``cv2.estimateAffine3D`` with ``force_rotation``),
    rather than ``pycolmap.estimate_sim3d``, which returns None for centres on a plane through
    the origin: three images always are, once a mapper has centred the reconstruction on them.
    """
    import cv2

    a, b = registered_poses(src), registered_poses(tgt)
    common = sorted(set(a) & set(b))
    if len(common) < 3:
        return None
    src_c = np.stack([-a[k][0].T @ a[k][1] for k in common])  # projection centres
    tgt_c = np.stack([-b[k][0].T @ b[k][1] for k in common])
    spread = np.linalg.svd(src_c - src_c.mean(axis=0), compute_uv=False)
    if spread[1] <= 1e-9 * spread[0]:  # collinear (or one point): a rotation is unknown
        return None
    Rt, scale = cv2.estimateAffine3D(src_c, tgt_c, force_rotation=True)
    return np.hstack([float(scale) * Rt[:, :3], Rt[:, 3:]]).astype(np.float64)
