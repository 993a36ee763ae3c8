"""The whole pipeline on real photographs (``python -m pipeline run-images DIR --graph KIND``).

The stages of a formation run (docs/DESIGN.md "Data flow") without ground truth: load and
downscale the images with their own intrinsics (:mod:`pipeline.inputs.photos`), features, matching on the
user's comm-graph edges only, the distributed consistency stage (Aragüés et al., Sec. III
detection and Sec. IV Alg. 1 resolution), fusion where poses exist, and as the check of the
cleaned tracks a pycolmap incremental reconstruction from the matches before cleaning and,
after cleaning, the kept links triangulated on its poses and bundle adjusted (or mapped from
scratch with ``remap``; :func:`_map_after`, :mod:`pipeline.colmap`). Writes the run folder
of docs/DESIGN.md "Run outputs" with ``truth`` empty in ``links.csv``, optionally the
cleaned matches as ``database.db``. With ``truth="homographies"`` (a planar scene with ``H1to{k}p.txt`` files, :mod:`pipeline.evaluation.truth`)
the ``truth`` column and every ground-truth figure of a formation run are filled in.

Camera ``k`` is the ``k``-th image in the order of its pixels' digests
(:func:`pipeline.inputs.photos.in_content_order`), not of its file name: with ``complete``,
``knn:K`` or a graph file of image names, renaming the files changes no decision, only the
names in the outputs (``line``, ``ring``, ``seq:K`` and index files follow the name order on
purpose: there the names are the user's sequence).

Poses for fusion: real images come without poses, so the reconstruction *before* cleaning
supplies them (and refines guessed focal lengths). Fusion runs among the images it registered
(at least two); the others take no part, like crashed robots, and the report names them.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pipeline.consistency.rules import DEFAULT_RESOLUTION
from pipeline.outcome import flag_result
from pipeline.progress import StageTimer
from pipeline.runfolder import atomic_run_folder, scratch_folder, write_json_atomic
from pipeline.types import Links, View

__all__ = ["ImagesConfig", "run_images"]


@dataclass
class ImagesConfig:
    """Options of ``run-images`` (see ``python -m pipeline run-images --help``)."""

    directory: str
    graph: str
    intrinsics: str = "auto"
    max_size: int | None = 1600
    #: COLMAP's SIFT and matcher by default (pipeline.matching.features.COLMAP_SIFT,
    #: pipeline.matching.pairs.MATCHERS): the features and matches a COLMAP user starts from
    features: str = "colmap-sift"
    matcher: str = "colmap"
    #: per image; None = scaled with the image size (pipeline.matching.features.photo_max_features)
    max_features: int | None = None
    #: SIFT contrast threshold (None = OpenCV's 0.04; 0.02 = COLMAP's DoG peak threshold,
    #: pipeline.matching.features.PHOTO_CONTRAST_THRESHOLD); RootSIFT descriptors; epipolar threshold in
    #: pixels (None = scaled with the image size, pipeline.matching.pairs.photo_threshold_px); the
    #: feature budget counts distinct locations (pipeline.matching.features.extract)
    contrast_threshold: float | None = 0.02
    rootsift: bool = True
    threshold_px: float | None = None
    budget_after_merge: bool = True
    fusion: bool = True
    rerun: bool = True
    export_db: bool = False
    out: str | None = None
    threads: int = 1
    truth: str = "none"
    truth_tol_px: float = 2.0
    resolution: str = DEFAULT_RESOLUTION
    merge_radius: float | None = None
    #: also stream the recording to a live viewer: "spawn", "connect" or a gRPC URL
    live: str | None = None
    #: "sim" (robots in this process) or "zenoh" (one robot process per photograph; no fusion)
    transport: str = "sim"
    #: map the kept links from scratch instead of on the poses of the reconstruction before
    #: cleaning (:func:`_map_after`)
    remap: bool = False

    def out_dir(self) -> Path:
        if self.out:
            return Path(self.out)
        folder = Path(os.path.realpath(self.directory)).name or "images"
        graph = Path(self.graph).stem if Path(self.graph).is_file() else self.graph.replace(":", "")
        return Path("runs") / f"images-{folder}-{graph}"


# ------------------------------------------------------------------------------------ the run

def _fuse_registered(cleaning, views: list[View], features, comm_edges, mapping,
                     timer: StageTimer) -> None:
    """Fusion (Montijano et al., dynamic voting) among the robots whose pose is known.

    Real images have no poses; the reconstruction before cleaning gives them (and refines
    guessed focal lengths and the radial distortion, which is taken out of the keypoints
    fusion sees). A robot whose image it did not register cannot form a local
    landmark estimate, so it takes no part: fusion runs on the registered cameras, their kept
    links and the comm edges between them (like a crashed robot). Links to an unregistered
    camera are left as the consistency stage left them. Cut links get reason
    ``fusion-outlier`` in ``cleaning.ledger``; ``cleaning`` is updated in place.
    """
    from pipeline.stages import fusion_on_reconstruction

    fr, n_cut, reg = fusion_on_reconstruction(cleaning.ledger, views, features, comm_edges,
                                              mapping.reconstruction, timer=timer,
                                              track_labels=cleaning.track_labels)
    if fr is None:
        cleaning.fusion_stats = {"enabled": False, "reason": (
            f"camera poses unknown: the reconstruction before cleaning registered "
            f"{len(reg)} of {len(views)} images")}
        return
    registered = {views[k].name for k in reg.tolist()}
    cleaning.fused_points = np.asarray(fr.points)
    cleaning.fusion_stats = {
        "enabled": True, "poses_from": "reconstruction before cleaning",
        "cameras": int(len(reg)),
        "cameras_without_pose": [v.name for v in views if v.name not in registered],
        **dict(fr.stats), "observations_cut_links": n_cut}


def _points_and_tracks(mapping, views: list[View], features, kept: Links):
    """3D points of the reconstruction, for each the association set of its first
    observation in the kept association graph (``-1`` when that feature is in none), and its
    RGB colour at that observation, ``(P, 3)`` uint8."""
    from pipeline import colmap
    from pipeline.association import AssociationGraph

    xyz, _, names, point2d = colmap.model_points(mapping.reconstruction)
    if not len(xyz):
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros((0, 3), np.uint8)
    cam_of_name = {v.name: k for k, v in enumerate(views)}
    m = np.array([len(f) for f in features], dtype=np.int64)
    graph = AssociationGraph(m, kept)
    labels = graph.components()
    first = np.array([graph.offsets[cam_of_name[n]] for n in names], dtype=np.int64) + point2d
    sizes = np.bincount(labels, minlength=labels.max() + 1 if labels.size else 0)
    tracks = np.where(sizes[labels[first]] >= 2, labels[first], -1)
    # colour of each point: its first observation's pixel in that image
    colors = np.zeros((len(xyz), 3), np.uint8)
    for k, (name, idx) in enumerate(zip(names, point2d, strict=True)):
        cam = cam_of_name[name]
        img = views[cam].image
        u, v = np.rint(features[cam].keypoints[idx]).astype(int)
        px = img[min(max(v, 0), img.shape[0] - 1), min(max(u, 0), img.shape[1] - 1)]
        colors[k] = px if np.ndim(px) == 0 else px[:3]
    return xyz, tracks, colors


def run_images(config: ImagesConfig, timer: StageTimer | None = None, *, loaded=None,
               robots_job=None) -> Path:
    """Run every stage on a folder of photographs and write the run folder; return its path.

    ``loaded``: ``(views, comm_edges)`` already loaded (an observer of a team loads the
    team's photographs itself, :mod:`pipeline.runs.observe`) instead of ``config.directory``
    and ``config.graph``; ``robots_job``: a callable with the transport's ``images``
    signature that replaces it (the observer hands in what the robots published).

    Stages: load → features → matching (comm edges only) → reconstruction before cleaning →
    consistency (Sec. III + Alg. 1) → fusion (poses from the first reconstruction) →
    reconstruction after cleaning (on the first one's poses, :func:`_map_after`) → outputs
    (report.json with ``flags``, links.csv with ``truth`` empty, sparse/ = the reconstruction after cleaning at the resolution of the image
    files, with colours, recording.rrd, database.db with ``export_db``).

    Raises
    ------
    InputError
        Bad folder, images, intrinsics or graph (see :func:`pipeline.inputs.photos.load_folder` and
        :func:`pipeline.commgraph.comm_graph`), or a bad feature method.
    """
    from pipeline import colmap
    from pipeline.commgraph import comm_graph
    from pipeline.matching.retrieval import knn_edges
    from pipeline.runs.transports import check_team_size, get_transport
    from pipeline.stages import check_merge_radius, clean_association

    timer = timer or StageTimer()
    given_radius = config.merge_radius
    config = _photo_defaults(config)
    out = config.out_dir()
    from pipeline.commgraph import positive_k
    from pipeline.matching.pairs import check_matcher

    check_matcher(config.matcher, config.features)  # before any work, as the graph's K
    if str(config.graph).startswith("knn:"):
        positive_k(str(config.graph))
    views, comm_edges = _load(config, timer) if loaded is None else loaded
    # as given: the sizes are known now, before the features
    check_merge_radius(given_radius, [v.size for v in views], "the smallest photograph as "
                       "loaded (after --max-size)")
    names = [v.name for v in views]
    if config.truth == "homographies":  # its files checked before any work, read at the end
        from pipeline.evaluation.truth import read_homographies

        read_homographies(config.directory, len(views))
    by_similarity = comm_edges is None
    chosen = {}

    def graph_from_features(features):
        # knn:K: neighbours by image similarity (pipeline.matching.retrieval), once the features exist
        chosen["edges"] = comm_graph(config.graph, names,
                                     knn=lambda k: knn_edges(features, k)[0])
        timer.note(f"graph {config.graph} by image similarity: {len(chosen['edges'])} edges")
        _warn_split(timer, len(names), chosen["edges"])
        return chosen["edges"]

    # features and matching, by the robots of the transport (over zenoh they also detect
    # and resolve; this process then only observes)
    check_team_size(config.transport, len(views), "photographs")
    job = robots_job or get_transport(config.transport).load().images
    robots = job(config, views, comm_edges, timer, graph_from_features)
    feats, matches, links, cleaning, team = (robots.features, robots.matches, robots.links,
                                             robots.cleaning, robots.team)
    if by_similarity:
        comm_edges = chosen["edges"]

    with scratch_folder("run-images-") as work, \
            ThreadPoolExecutor(max_workers=1) as mapper:
        work = Path(work)
        # calibrated cameras (K.txt) stay fixed in the bundle adjustments; EXIF and guessed
        # focal lengths are refined
        fixed = [v.name for v in views if colmap.calibrated(v)]
        # views downscaled from files of different sizes are not one camera: sparse/ and
        # database.db scale each camera back to its files by one factor
        file_sizes = list(_file_sizes(views, Path(config.directory)).values())
        db_before = colmap.write_database(work / "before.db", views, feats, links,
                                          file_sizes=file_sizes)
        # COLMAP's mapper releases the GIL: the reconstruction before cleaning runs in a
        # thread while this one runs what needs only the links (the consistency stage, the
        # report's centralized baselines); fusion waits for its poses
        before_job = mapper.submit(_timed, colmap.incremental_mapping_with_retry, db_before,
                                   num_threads=config.threads, fixed_intrinsics=fixed)
        if cleaning is None:
            cleaning = clean_association(views, feats, comm_edges, links, fusion=False,
                                         timer=timer, resolution=config.resolution,
                                         matches=matches)
        baselines = _baselines(feats, links)
        with timer.stage("reconstruction-before", "pycolmap incremental mapping, all links "
                         "(begun alongside the consistency stage)"):
            map_before, mapping_s = before_job.result()
            timer.note(_mapping_note(map_before))
        # the stage's time is the mapping's own (it overlapped the stages above)
        timer.timings["reconstruction-before"] = mapping_s
        if team is not None:
            pass  # fusion does not run over the zenoh transport (cleaning.fusion_stats says so)
        elif not config.fusion:
            cleaning.fusion_stats = {"enabled": False, "reason": "disabled by option"}
        elif importlib.util.find_spec("pipeline.fusion.landmarks") is None:
            cleaning.fusion_stats = {"enabled": False,
                                     "reason": "fusion stage (pipeline.fusion.landmarks) not "
                                               "available in this build"}
        else:
            _fuse_registered(cleaning, views, feats, comm_edges, map_before, timer)
        kept = cleaning.ledger.kept
        with timer.stage("reconstruction-after", _AFTER[_after_mode(config, kept, map_before)]):
            db_after = colmap.write_database(work / "database.db", views, feats, links, keep=kept,
                                             file_sizes=file_sizes)
            map_after = _map_after(config, kept, db_after, map_before, fixed)
            timer.note(_mapping_note(map_after))

        report, md = _report(config, out, views, feats, matches, comm_edges, cleaning, team,
                             map_before, map_after, timer, baselines=baselines)

        _write(out, config, report, md, views, feats, cleaning, map_before, map_after, db_after,
               timer)
    print(md)
    return out


#: how the reconstruction after cleaning is made (:func:`_after_mode`), as the stage line and
#: report.json say it
_AFTER = {
    "same": "nothing cut: the reconstruction before cleaning",
    "poses": "kept links triangulated on the poses of the reconstruction before cleaning, "
             "bundle adjusted (pipeline.colmap.mapping_from_poses)",
    "scratch": "pycolmap incremental mapping of the kept links from scratch",
    "unusable": "pycolmap incremental mapping of the kept links from scratch (the "
                "reconstruction before cleaning is no start: fewer than two registered images, "
                "or cameras COLMAP deems bogus)",
}


def _after_mode(config: ImagesConfig, kept: np.ndarray, map_before) -> str:
    """``same`` (no link cut), ``scratch`` (``remap``), ``unusable`` (from scratch too: no
    reconstruction before cleaning to start from, fewer than two images or a camera COLMAP
    deems bogus, :func:`pipeline.colmap.poses_usable`) or ``poses`` (the default:
    :func:`_map_after`)."""
    if bool(np.all(kept)):
        return "same"
    from pipeline import colmap

    if config.remap:
        return "scratch"
    return "poses" if colmap.poses_usable(map_before.reconstruction) else "unusable"


def _map_after(config: ImagesConfig, kept: np.ndarray, db_after: Path, map_before, fixed):
    """The reconstruction after cleaning (the check of the cleaned tracks).

    By default the kept links are triangulated on the poses of the reconstruction before
    cleaning and bundle adjusted, and the images it did not register are offered to the
    mapper (:func:`pipeline.colmap.mapping_from_poses`): those poses are the ones fusion
    judged the links with, and the kept links are a subset of the links they were found
    from. Mapping the kept links from scratch (``remap``) makes COLMAP find every pose
    again from that subset; on a weak view graph the correct matches alone may fall below
    its registration thresholds: the rendered ring of :mod:`data_synth.symmetric` (ABCD)
    registered 18 of 18 images before cleaning and 5 of 18 after, as it did with exactly
    the links the truth calls wrong removed, while on the poses the kept links register
    18 of 18 with lower pose errors than before cleaning (mapping_from_poses' docstring).
    With no link cut the reconstruction before cleaning is the one after (the same
    database), so it is not mapped twice.
    """
    from pipeline import colmap

    mode = _after_mode(config, kept, map_before)
    if mode == "same":
        return map_before
    if mode in ("scratch", "unusable"):
        return colmap.incremental_mapping(db_after, num_threads=config.threads,
                                          fixed_intrinsics=fixed,
                                          min_pose_inliers=map_before.min_pose_inliers)
    return colmap.mapping_from_poses(db_after, map_before.reconstruction,
                                     num_threads=config.threads, fixed_intrinsics=fixed,
                                     min_pose_inliers=map_before.min_pose_inliers)


def _photo_defaults(config: ImagesConfig) -> ImagesConfig:
    """COLMAP's SIFT merges only co-located orientations (0.5 px) unless told otherwise.

    The resolution rule's own radius (the evidence rule's 2 px, the truth tolerance of the
    rendered formations) would also merge distinct DoG extrema COLMAP keeps apart: on the
    Sceaux photographs at 1600 px that cost 1.5 % of the points before cleaning and 1.8 %
    after (7721 / 7435 against 7837 / 7569, one run each).
    """
    from pipeline.matching.features import COLMAP_SIFT
    from pipeline.stages import photo_merge_radius

    if config.features == COLMAP_SIFT and config.merge_radius is None:
        return dataclasses.replace(config, merge_radius=photo_merge_radius(
            config.features, config.resolution, None))
    return config


def _merge_radius_used(config: ImagesConfig) -> float:
    """The radius the run merged co-located keypoints at (:func:`pipeline.stages.
    photo_merge_radius`: as given, else COLMAP SIFT's, else the rule's own)."""
    from pipeline.stages import photo_merge_radius

    return float(photo_merge_radius(config.features, config.resolution, config.merge_radius))


def _load(config: ImagesConfig, timer: StageTimer):
    """The photographs and the comm graph (``None`` for ``knn:K``, chosen after the features)."""
    from pipeline.commgraph import comm_graph
    from pipeline.inputs.photos import (
        identical_pixels,
        in_content_order,
        load_folder,
        pixel_digests,
    )

    with timer.stage("load", f"{config.directory}, longest side {config.max_size or 'full'} px"):
        intrinsics = config.intrinsics if config.intrinsics in ("auto", "exif") \
            else Path(config.intrinsics)
        by_similarity = str(config.graph).startswith("knn:")

        def check_names(names: list[str]) -> None:
            # a graph file and the homographies are read on the file names before any image
            # is decoded
            if not by_similarity:
                comm_graph(config.graph, names)
            if config.truth == "homographies":
                from pipeline.evaluation.truth import read_homographies

                read_homographies(config.directory, len(names))

        loaded = load_folder(config.directory, max_size=config.max_size, intrinsics=intrinsics,
                             check_names=check_names)
        # cameras in the order of their pixels' digests: file names change nothing
        digests = pixel_digests(loaded)
        views = in_content_order(loaded, digests)
        for same in identical_pixels(loaded, digests):
            timer.warn(f"images {', '.join(same)} have identical pixels: the same photograph "
                       "twice matches itself and adds nothing; keep one")
        comm_edges = None
        if not by_similarity:
            # kinds that follow an order (line, ring, seq:K) and index files follow the file
            # names, as the user named them; the edges are then put on the camera indices
            in_name_order = comm_graph(config.graph, [v.name for v in loaded])
            camera = {v.name: k for k, v in enumerate(views)}
            to_camera = np.array([camera[v.name] for v in loaded], dtype=np.int64)
            comm_edges = np.sort(to_camera[in_name_order], axis=1).reshape(-1, 2)
            comm_edges = comm_edges[np.lexsort((comm_edges[:, 1], comm_edges[:, 0]))]
            _warn_split(timer, len(views), comm_edges)
        sources = sorted({v.intrinsics_source for v in views})
        timer.note(f"{len(views)} images, intrinsics from {', '.join(sources)}; graph "
                   f"{config.graph}: " + ("chosen by image similarity after the features"
                                          if by_similarity else f"{len(comm_edges)} edges"))
    return views, comm_edges


def _warn_split(timer: StageTimer, n: int, comm_edges: np.ndarray) -> None:
    """Warn when the comm graph leaves images in groups that never match each other: their
    features cannot be associated across the groups, and the reconstruction holds one group."""
    from pipeline.commgraph import split_warning

    message = split_warning(n, comm_edges)
    if message:
        timer.warn(message)


def _timed(fn, *args, **kwargs):
    """``(fn(*args, **kwargs), its wall time in seconds)``."""
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def _baselines(feats, links: Links) -> dict:
    """The report's centralized baselines on the links before cleaning
    (:func:`pipeline.evaluation.report.baselines_section`)."""
    from pipeline.evaluation import report as sections

    return sections.baselines_section(np.array([len(f) for f in feats], dtype=np.int64), links)


def _report(config: ImagesConfig, out: Path, views, feats, matches, comm_edges, cleaning, team,
            map_before, map_after, timer: StageTimer, *,
            baselines: dict | None = None) -> tuple[dict, str]:
    """``report.json`` of a photo run (with its ``flags``, warned on stderr) and its markdown
    (``baselines``: the section when already computed, :func:`_baselines`)."""
    from pipeline.evaluation import report as sections

    m = np.array([len(f) for f in feats], dtype=np.int64)
    ledger = cleaning.ledger
    links = ledger.links
    kept_links = links.subset(ledger.kept)
    names = [v.name for v in views]
    report = {
        "title": f"images {Path(config.directory).resolve().name}, graph {config.graph}",
        "n_cameras": len(views),
        "comm_edges": comm_edges.tolist(),
        "features_per_camera": m.tolist(),
        "before": sections.association_counts(m, links, None, None),
        "after": sections.association_counts(m, kept_links, None, None),
        "resolution": sections.resolution_section(ledger, cleaning.resolution_stats),
        "fusion": sections.fusion_section(ledger, cleaning.fusion_stats),
        "triangulation": {"method": "pycolmap incremental mapping from the matches "
                                    "(two-view geometries = links before / kept links after)",
                          "after_from": _AFTER[_after_mode(config, ledger.kept, map_before)],
                          "before": map_before.summary(), "after": map_after.summary()},
        "baselines": _baselines(feats, links) if baselines is None else baselines,
        "matching": sections.matching_section(matches),
        "images": [{"name": v.name, "size": list(v.size), "K": v.K.tolist(),
                    "intrinsics_source": v.intrinsics_source,
                    "intrinsics_known": bool(v.intrinsics_known)} for v in views],
        "versions": sections.versions(),
        "config": {**asdict(config), "out": str(out),
                   # the radius the keypoints were merged at (merge_radius null: the rule's)
                   "merge_radius_used_px": _merge_radius_used(config)},
    }
    if team is not None:
        report["team"] = team
    if cleaning.fused_points is not None:
        report["fusion"]["fused_points"] = int(len(cleaning.fused_points))
    if config.truth == "homographies":
        from pipeline.evaluation.truth import fill_report

        with timer.stage("evaluate", "ground truth from the homographies"):
            fill_report(report, config.directory, views, feats, comm_edges, ledger,
                        config.truth_tol_px)
        if report["ground_truth"]["doubt"]:
            timer.warn(report["ground_truth"]["doubt"])
    flag_result(report, names)
    report["cleaning_effect"] = _cleaning_effect(views, feats, ledger, map_before, map_after)
    report["flags"] = _flags(views, feats, ledger, comm_edges, matches, map_before,
                             map_after)
    _explain_flags(report["flags"], report["cleaning_effect"])
    for f in report["flags"]:
        timer.warn(f"{f['message']}. Likely cause: {f['likely_cause']}.")
    return report, sections.images_report_markdown(report)


def _write(out: Path, config: ImagesConfig, report: dict, md: str, views, feats, cleaning,
           map_before, map_after, db_after: Path, timer: StageTimer) -> None:
    """The run folder, atomically: ``links.csv``, ``sparse/`` (at the resolution of the image
    files), ``database.db`` (with ``export_db``), ``recording.rrd`` and ``report.json``."""
    from pipeline import colmap
    from pipeline.inputs.linkscsv import write_links_csv

    ledger = cleaning.ledger
    kept_links = ledger.links.subset(ledger.kept)
    with timer.stage("write", str(out)):
        with atomic_run_folder(out) as tmp:
            write_links_csv(tmp / "links.csv", ledger)
            # sparse/ and database.db at the resolution of the image files they name (the
            # mapping ran on downscaled copies), sparse/ with colours from those files
            sizes = _file_sizes(views, Path(config.directory))
            colmap.write_model_for_files(tmp / "sparse", map_after.reconstruction, sizes,
                                         config.directory)
            if config.export_db:
                shutil.copyfile(db_after, tmp / "database.db")
                colmap.rescale_database(tmp / "database.db", sizes)
            if config.rerun:
                _write_recording(tmp / "recording.rrd", views, feats, cleaning,
                                 map_before, map_after, kept_links, md, live=config.live,
                                 warn=timer.warn)
            report["timings_s"] = {k: round(v, 4) for k, v in timer.timings.items()}
            write_json_atomic(tmp / "report.json", report)


def _file_sizes(views: list[View], directory: Path) -> dict[str, tuple[int, int]]:
    """``{name: (width, height)}`` of the image files (read from their headers)."""
    from PIL import Image

    sizes = {}
    for v in views:
        with Image.open(directory / v.name) as im:
            sizes[v.name] = im.size
    return sizes


def _explain_flags(flags: list[dict], effect: dict) -> None:
    """Name, in the flags, the stage and the links behind a change of the reconstruction
    (``report.json`` ``cleaning_effect`` lists the links' rows); a jump in registered images
    gets its own flag, ``images-gained``."""
    stages = "; ".join(f"{v['points']} points by {k} ({v['count']} links)"
                       for k, v in effect["by_stage"].items()) or "none"
    for f in flags:
        if f["flag"] == "cleaning-worse":
            f["likely_cause"] += (f"; tracks of the reconstruction before cleaning that held a "
                                  f"cut link: {stages} (the links: cleaning_effect in "
                                  f"report.json, rows of links.csv)")
    gained = effect["images_gained"]
    if gained:
        detail = "; ".join(
            f"{g['image']}: " + (", ".join(f"{v['count']} links cut by {k}"
                                           for k, v in g["cut"].items()) or "no link cut")
            + f", {g['links_kept']} kept" for g in gained)
        flags.append({
            "flag": "images-gained",
            "message": f"cleaning registered {len(gained)} more image(s): "
                       + ", ".join(g["image"] for g in gained),
            "likely_cause": f"COLMAP's mapper registers an image from its 2D-3D matches to "
                            f"points already triangulated; with all links those matches "
                            f"contradicted the others (links of a conflictive set through it, "
                            f"or fusion outliers), after the cuts its registration passes "
                            f"({detail})"})


#: most links.csv rows listed per entry of ``cleaning_effect`` (the counts are always whole)
MAX_LISTED_LINKS = 200


def _rows(mask: np.ndarray) -> dict:
    rows = np.flatnonzero(mask)
    return {"count": int(len(rows)), "links_csv_rows": rows[:MAX_LISTED_LINKS].tolist()}


def _cleaning_effect(views, feats, ledger, map_before, map_after) -> dict:
    """What cleaning changed in the reconstruction and which cut links did it.

    - ``points``: the points of the reconstruction before cleaning whose track held a link
      that was then cut (both ends observations of that point), by the stage that cut it, with
      those links' rows in ``links.csv`` (0-based data rows): the points cleaning shortened or
      removed, and why;
    - ``images_lost`` / ``images_gained``: images registered before but not after cleaning
      (or after only), each with the links of it cut by stage and its links kept. An image
      gained was not registered from all links: COLMAP's mapper registers an image from
      2D-3D matches to points already triangulated, and the cut links were matches of it
      that the other images contradicted (a conflictive set through it, or a fusion
      outlier); without them its registration passes.
    """
    links = ledger.links
    reason = np.asarray(ledger.reason, dtype=str)
    cut = reason != ""
    m = np.array([len(f) for f in feats], dtype=np.int64)
    offsets = np.r_[0, np.cumsum(m)]
    point_of = np.full(int(offsets[-1]), -1, dtype=np.int64)
    cam_of = {v.name: k for k, v in enumerate(views)}
    rec = map_before.reconstruction
    if rec is not None:
        for pid, p in rec.points3D.items():
            for el in p.track.elements:
                point_of[offsets[cam_of[rec.images[el.image_id].name]] + el.point2D_idx] = pid
    g_i = offsets[links.cam_i] + links.feat_i
    g_j = offsets[links.cam_j] + links.feat_j
    in_track = cut & (point_of[g_i] >= 0) & (point_of[g_i] == point_of[g_j])
    by_stage = {}
    for r in sorted(set(reason[in_track].tolist())):
        sel = in_track & (reason == r)
        by_stage[r] = {"points": int(len(np.unique(point_of[g_i[sel]]))), **_rows(sel)}
    effect = {"points_before": int(map_before.points), "points_after": int(map_after.points),
              "points_with_cut_links": int(len(np.unique(point_of[g_i[in_track]]))),
              "by_stage": by_stage}
    before, after = set(map_before.registered_names), set(map_after.registered_names)
    for key, names in (("images_lost", sorted(before - after)),
                       ("images_gained", sorted(after - before))):
        effect[key] = []
        for name in names:
            k = cam_of[name]
            touch = (links.cam_i == k) | (links.cam_j == k)
            effect[key].append({
                "image": name, "links_kept": int((touch & ~cut).sum()),
                "cut": {r: _rows(touch & (reason == r))
                        for r in sorted(set(reason[touch & cut].tolist()))}})
    return effect


def _flags(views, feats, ledger, comm_edges, matches, map_before, map_after) -> list[dict]:
    """Flags of :func:`pipeline.evaluation.flags.reconstruction_flags` for this run."""
    from pipeline.evaluation.flags import reconstruction_flags

    links = ledger.links
    reason = np.asarray(ledger.reason, dtype=str)
    cut = reason != ""
    lost = set(map_before.registered_names) - set(map_after.registered_names)
    per_image = {}
    for k, v in enumerate(views):
        if v.name in lost:
            touch = cut & ((links.cam_i == k) | (links.cam_j == k))
            names, counts = np.unique(reason[touch], return_counts=True)
            per_image[v.name] = dict(zip(names.tolist(), counts.tolist(), strict=True))
    names, counts = np.unique(reason[cut], return_counts=True)
    return reconstruction_flags(
        len(views), map_before.summary(), map_after.summary(), comm_edges,
        [len(p.pairs) for p in matches], [len(f) for f in feats],
        intrinsics_guessed=sum(not v.intrinsics_known for v in views),
        cut_by_reason=dict(zip(names.tolist(), counts.tolist(), strict=True)),
        lost_image_cuts=per_image, image_names=[v.name for v in views])


def _write_recording(path: Path, views, feats, cleaning, map_before, mapping,
                     kept_links, md: str, live: str | None = None, warn=None) -> None:
    from pipeline import colmap
    from pipeline.stages import posed_views
    from pipeline.types import RunRecord
    from viz.rerun_log import log_run

    # cameras registered after cleaning are drawn with their pose and camera in that
    # reconstruction; fused points, estimated in the frame of the reconstruction before
    # cleaning, are moved into it by the similarity between the two
    drawn = posed_views(views, colmap.registered_poses(mapping.reconstruction))
    fused = None
    if cleaning.fused_points is not None and len(cleaning.fused_points):
        M = colmap.similarity_between(map_before.reconstruction, mapping.reconstruction)
        if M is not None:
            fused = np.asarray(cleaning.fused_points, dtype=np.float64) @ M[:, :3].T + M[:, 3]
        elif warn is not None:
            common = len(set(colmap.registered_poses(map_before.reconstruction))
                         & set(colmap.registered_poses(mapping.reconstruction)))
            why = (f"only {common} images are registered both before and after cleaning "
                   "(three are needed)" if common < 3 else
                   f"the centres of the {common} images registered both before and after "
                   "cleaning are collinear")
            warn(f"the {len(cleaning.fused_points)} fused points (report.json "
                 "fusion.fused_points) are not in the recording: they were estimated in the "
                 "frame of the reconstruction before cleaning, and " + why + ", so they "
                 "cannot be put into the frame of the one drawn")
    points, tracks, colors = _points_and_tracks(mapping, views, feats, kept_links)
    record = RunRecord(
        views=drawn, features=feats, ledger=cleaning.ledger,
        points=points, point_tracks=tracks, gt_points=None,
        fused_points=fused, report_markdown=md, point_colors=colors)
    log_run(path, record, live=live)


def _mapping_note(mapping) -> str:
    relaxed = "" if mapping.registered_at_colmap_default is None else (
        f" (at {mapping.min_pose_inliers} points seen; COLMAP's 30 registered "
        f"{mapping.registered_at_colmap_default})")
    means = (f", track length {mapping.mean_track_length:.2f}, reprojection error "
             f"{mapping.mean_reprojection_error:.3f} px") if mapping.points else ""
    return (f"{mapping.registered_images} of {mapping.images} images registered{relaxed}, "
            f"{mapping.points} points{means}")
