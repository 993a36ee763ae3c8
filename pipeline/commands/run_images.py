"""``python -m pipeline run-images DIR --graph KIND``: the whole pipeline on real photographs.

The options of the run; the run itself is :func:`pipeline.runs.images.run_images`, or with
``--sequence`` (a folder of per-robot frame sequences, associated online step by step)
:func:`pipeline.runs.online_images.run_images_sequence`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path

from pipeline import validate
from pipeline.commands.options import (
    add_feature_options,
    add_merge_radius_option,
    add_online_options,
    add_resolution_option,
    add_transport_option,
    check_online_options,
    feature_options,
    online_run_summary,
    refuse_online_options,
)
from pipeline.errors import InputError
from pipeline.outcome import exit_status
from pipeline.progress import counted
from pipeline.runs.images import ImagesConfig

__all__ = ["add_arguments", "config_from_args", "run", "check_live", "RERUN_DEFAULT_URL"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("directory", metavar="DIR",
                   help="folder of photographs (JPEG/PNG/TIFF/BMP/WebP; taken in name order); with "
                        "--sequence a folder of one sub-folder per robot")
    p.add_argument("--graph", default="complete",
                   metavar="line|ring|ring2|complete|knn:K|seq:K|FILE",
                   help="communication graph (default complete: every pair, as COLMAP's "
                        "exhaustive matcher): line, ring, ring2 (ring + 2-hop chords), "
                        "ring+triangles (formation b's), complete, "
                        "knn:K (each image with the K images most similar to it, by a global "
                        "descriptor of its features: for unordered photos), seq:K (each image "
                        "with the K nearest in name order: for ordered sequences), or a file of "
                        "'cam_i,cam_j' lines (0-based indices in name order, or image names)")
    p.add_argument("--intrinsics", default="auto", metavar="auto|exif|K.txt",
                   help="auto (DIR/K.txt, else EXIF, else a guessed focal length), exif, or "
                        "a K.txt at the images' full resolution (default auto)")
    p.add_argument("--max-size", type=int, default=1600, metavar="PX",
                   help="longest image side after downscaling (default 1600; 0 = full size)")
    add_feature_options(p, photos=True)
    p.add_argument("--export-db", action="store_true",
                   help="also write the matches as a COLMAP database (run folder/database.db, "
                        "at the resolution of the image files, as sparse/): matches table = every "
                        "link, two-view geometries = kept links; keypoints without descriptors "
                        "(for mapping, not for matching again)")
    p.add_argument("--no-fusion", action="store_true", help="skip the fusion stage")
    p.add_argument("--remap", action="store_true",
                   help="map the kept links from scratch (COLMAP's incremental mapping) instead "
                        "of triangulating them on the poses of the reconstruction before "
                        "cleaning and bundle adjusting (the default: cleaning then refines the "
                        "poses but cannot lose an image the first mapping registered)")
    p.add_argument("--no-rerun", action="store_true", help="do not write recording.rrd")
    live = p.add_mutually_exclusive_group()
    live.add_argument("--spawn", action="store_true",
                      help="also show the recording in a new Rerun viewer (needs a display)")
    live.add_argument("--connect", nargs="?", const="connect", default=None, metavar="URL",
                      help="also stream the recording to a running Rerun viewer (default URL: "
                           "Rerun's, rerun+http://127.0.0.1:9876/proxy)")
    p.add_argument("--threads", type=int, default=None,
                   help="threads of COLMAP's mapper (default 1: repeatable figures; -1: all cores)")
    p.add_argument("--truth", default="none", choices=("none", "homographies"),
                   help="ground truth: homographies = DIR/H1to{k}p.txt (planar scene, image 1 "
                        "to image k at full resolution); a link is good when each keypoint maps "
                        "within --truth-tol of the other (pipeline.evaluation.truth). Default none")
    p.add_argument("--truth-tol", type=float, default=None, metavar="PX",
                   help="tolerance of --truth in pixels of the processed images (default 2)")
    p.add_argument("--out", default=None,
                   help="run folder (default runs/images-<DIR name>-<graph>)")
    p.add_argument("--matcher", default="colmap", choices=("colmap", "opencv"),
                   help="pair matching on the comm edges: colmap (default: COLMAP's matcher and "
                        "two-view verification, its 4 px threshold and 15 inliers) or opencv "
                        "(mutual ratio test and USAC MAGSAC)")
    add_resolution_option(p)
    add_merge_radius_option(p, photos=True)
    add_transport_option(p)
    g = p.add_argument_group("a team in motion: per-robot frame sequences (online association)")
    g.add_argument("--sequence", action="store_true",
                   help="DIR holds one sub-folder per robot (robots in the sub-folders' name "
                        "order), each with that robot's frames in name order, every robot the "
                        "same number; step k = each robot's k-th frame, associated online as "
                        "run-formation --steps N; --graph is then the robots' graph (a kind, or "
                        "a file of sub-folder names or indices); no fusion (no poses)")
    add_online_options(g, "--sequence")


def check_max_size(max_size: int) -> None:
    """``--max-size``: 0 (full resolution) or at least 16 pixels of the longest side."""
    from pipeline.inputs.photos import MIN_MAX_SIZE

    if max_size < 0 or 0 < max_size < MIN_MAX_SIZE:
        raise InputError(f"--max-size {max_size}: expected at least {MIN_MAX_SIZE} pixels of "
                         f"the longest side, or 0 for full resolution")


#: where ``--connect`` streams without a URL (Rerun's own default)
RERUN_DEFAULT_URL = "rerun+http://127.0.0.1:9876/proxy"


def check_live(spawn: bool, connect: str | None, timeout_s: float = 1.0) -> None:
    """Refuse before any work a live viewer that cannot be reached: ``--spawn`` without a
    display (Rerun would ignore it), ``--connect`` to a URL that is not Rerun's
    ``rerun+http://HOST:PORT/proxy`` form or where nothing answers (Rerun would retry in the
    background and drop the stream)."""
    import socket
    import sys
    from urllib.parse import urlsplit

    from viz.view import has_display

    if spawn and sys.platform.startswith("linux") and not has_display():
        raise InputError("--spawn needs a display (DISPLAY is not set): drop it and open "
                         "recording.rrd later (make view serves it to a browser), or stream to "
                         "a viewer elsewhere with --connect URL")
    if connect is None:
        return
    url = RERUN_DEFAULT_URL if connect == "connect" else connect
    try:  # urlsplit itself refuses some URLs, e.g. an unclosed IPv6 bracket
        parts = urlsplit(url.removeprefix("rerun+"))
        host, port = parts.hostname, parts.port
    except ValueError:
        host = port = None
    if not url.startswith(("rerun+http://", "rerun+https://")) or not host or not port:
        raise InputError(f"--connect {url!r}: expected Rerun's form "
                         f"rerun+http://HOST:PORT/proxy, e.g. {RERUN_DEFAULT_URL}")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        raise InputError(f"--connect {url}: no Rerun viewer answers there "
                         f"({exc.strerror or exc}); start one (rerun) or drop --connect "
                         "(recording.rrd is written either way)") from None


def config_from_args(args) -> ImagesConfig:
    check_max_size(args.max_size)
    if args.truth_tol is not None and args.truth == "none":
        raise InputError(f"--truth-tol {args.truth_tol} without --truth: the tolerance is "
                         "that of --truth homographies; add it or drop --truth-tol")
    truth_tol = 2.0 if args.truth_tol is None else args.truth_tol
    if not (math.isfinite(truth_tol) and truth_tol > 0):
        raise InputError(f"--truth-tol {truth_tol}: expected a finite number of pixels > 0, "
                         "e.g. --truth-tol 2 (at inf every link would count as good)")
    method, max_features = feature_options(args)
    if args.no_rerun and (args.spawn or args.connect):
        raise InputError(f"{'--spawn' if args.spawn else '--connect'} with --no-rerun: the live "
                         "viewer shows the recording; drop one of them")
    check_live(args.spawn, args.connect)
    return ImagesConfig(directory=args.directory, graph=args.graph, intrinsics=args.intrinsics,
                        max_size=args.max_size or None, features=method,
                        max_features=max_features, fusion=not args.no_fusion,
                        rerun=not args.no_rerun, export_db=args.export_db, out=args.out,
                        threads=validate.threads(1 if args.threads is None else args.threads),
                        truth=args.truth, truth_tol_px=truth_tol,
                        resolution=args.resolution, merge_radius=args.merge_radius,
                        live="spawn" if args.spawn else args.connect,
                        transport=args.transport, matcher=args.matcher, remap=args.remap)


def _refuse_empty_paths(args) -> None:
    """InputError for an empty DIR, ``--out`` or ``--intrinsics`` (an unset shell variable):
    ``Path('')`` is the current folder, and an empty ``--out`` fell back to the default run
    folder, replacing the run there."""
    for flag, value in (("DIR", args.directory), ("--out", args.out),
                        ("--intrinsics", args.intrinsics)):
        validate.not_empty(value, flag, "give a folder name" if flag != "--intrinsics"
                           else "give auto, exif or the path of a K.txt")


def _inputs(config: ImagesConfig) -> list[tuple[str, str]]:
    """``(flag, path)`` of what the run reads (a run folder may not hold them)."""
    return [("DIR", config.directory)] + [
        (flag, v) for flag, v in (("--graph", config.graph), ("--intrinsics", config.intrinsics))
        if Path(v).exists()]


def sequence_config_from_args(args):
    """The :class:`pipeline.runs.online_images.SequenceConfig` of ``run-images DIR --sequence``.

    Raises
    ------
    InputError
        A bad ``--window``, ``--hold`` or ``--batch-every``, or an option the online job does not run
        (``--export-db``, ``--truth``, ``--no-fusion``, a live viewer).
    """
    from pipeline.runs.online_images import SequenceConfig

    check_online_options(args)
    for flag, on, why in (
            ("--export-db", args.export_db, "writes no database"),
            ("--truth", args.truth != "none", "takes no truth"),
            ("--truth-tol", args.truth_tol is not None, "takes no truth"),
            ("--remap", args.remap, "maps nothing"),
            ("--no-fusion", args.no_fusion, "fuses nothing: photographs have no poses"),
            ("--threads", args.threads is not None, "runs no COLMAP mapper"),
            ("--spawn/--connect", bool(args.spawn or args.connect), "streams to no viewer")):
        if on:
            raise InputError(f"{flag} is not available with --sequence (the online job "
                             f"{why}); drop it")
    check_max_size(args.max_size)
    method, max_features = feature_options(args)
    return SequenceConfig(directory=args.directory, graph=args.graph, window=args.window,
                          hold=args.hold, intrinsics=args.intrinsics, max_size=args.max_size or None,
                          features=method, max_features=max_features, matcher=args.matcher,
                          resolution=args.resolution, batch_every=args.batch_every,
                          out=args.out, rerun=not args.no_rerun, transport=args.transport,
                          merge_radius=args.merge_radius)


def _run_sequence(args) -> int:
    from pipeline.outputs import current_folder
    from pipeline.runfolder import claim_run_folder
    from pipeline.runs.online_images import run_images_sequence

    config = sequence_config_from_args(args)
    current_folder(config.out_dir(), "--out")
    # realpath, not Path.resolve: a symbolic link that loops is named by the checks below
    out = Path(os.path.realpath(config.out_dir()))
    folder = Path(os.path.realpath(config.directory))
    if folder in out.parents:
        raise InputError(f"--out {str(config.out_dir())!r} is inside DIR {config.directory!r}: "
                         "with --sequence every sub-folder of DIR is a robot, so the next run "
                         "on DIR would read the run folder as one; choose an --out outside DIR")
    with claim_run_folder(config.out_dir(), inputs=[("DIR", config.directory)]):
        out = run_images_sequence(config)
    report = json.loads((out / "report.json").read_text())
    f = report["final"]
    return online_run_summary(
        report, out, f"{counted(len(report['steps']), 'step')} of {report['n_robots']} robots, "
        f"{counted(f['links'], 'link')}, conflict-free after every step: "
        f"{report['conflict_free_every_step']}; kept online {f['online']['kept']}"
        + (f", batch {f['batch']['kept']}" if "batch" in f else ""), args.no_rerun)


def run(args) -> int:
    from pipeline.runfolder import claim_run_folder
    from pipeline.runs.images import run_images

    _refuse_empty_paths(args)
    from pipeline.stages import merge_radius_for

    merge_radius_for(args.resolution, args.merge_radius)  # a bad one refused before any work
    if args.sequence:
        return _run_sequence(args)
    refuse_online_options(args, "--sequence")
    config = config_from_args(args)
    with claim_run_folder(config.out_dir(), inputs=_inputs(config)):
        out = run_images(config)
    written = ["report.json", "links.csv", "sparse/"]
    written += [] if args.no_rerun else ["recording.rrd"]
    written += ["database.db"] if args.export_db else []
    print(f"run written to {out}/ ({', '.join(written)})")
    return exit_status(json.loads((out / "report.json").read_text()))
