"""``python -m pipeline clean-db IN.db --out OUT.db [--comm-graph FILE] [--loop-check] [--fusion]
[--ignore-watermarks]``.

A COLMAP database's verified matches made consistent; the job and what it writes are
described in :mod:`pipeline.runs.clean_db`. This module parses the options and prints the
summary.
"""

from __future__ import annotations

import argparse
import sys

from pipeline.commands.options import (
    add_overwrite_and_memory_options,
    add_resolution_option,
    add_transport_option,
)

__all__ = ["add_arguments", "run", "fusion_lines"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("database", metavar="IN.db", help="COLMAP database with two-view geometries "
                                                     "(made by COLMAP or hloc); never modified")
    p.add_argument("--out", required=True, metavar="OUT.db",
                   help="the cleaned database to write; OUT.links.csv and OUT.rrd are written "
                        "beside it")
    p.add_argument("--comm-graph", default=None, metavar="FILE",
                   help="communication graph: 'cam_i,cam_j' lines, 0-based indices of the images "
                        "in name order or image names (default: images sharing verified "
                        "matches are neighbours)")
    p.add_argument("--image-dir", default=None, metavar="DIR",
                   help="the images, to draw them in OUT.rrd (default: gray canvases)")
    p.add_argument("--no-rerun", action="store_true", help="do not write OUT.rrd")
    p.add_argument("--report", default=None, metavar="JSON",
                   help="also save the summary as JSON")
    p.add_argument("--baselines", action="store_true",
                   help="also run the centralized baselines on the same verified links "
                        "(spectral synchronization, a CLEAR-style method, union-find dropping "
                        "conflictive sets, ...), for comparison: a line each and the summary's "
                        "baselines")
    p.add_argument("--loop-check", action="store_true",
                   help="first drop the image pairs whose relative rotation breaks the rotation "
                        "loops (triangles) of the view graph: wrong two-view geometries between "
                        "images of repeated structure, which the consistency stage cannot see "
                        "(reason loop-inconsistent; off by default)")
    p.add_argument("--loop-tol", default=None, metavar="DEG",
                   help="with --loop-check: the cycle error (degrees) below which a triangle "
                        "is consistent (default 15)")
    p.add_argument("--fusion", action="store_true",
                   help="after the consistency stage, map the input with COLMAP (seed 0) and "
                        "run the robust distributed fusion on its poses: the observations "
                        "voted out of their tracks leave them, their links to the others "
                        "cut (reason fusion-outlier; a link between two of them stays): "
                        "wrong matches the consistency stage cannot see, e.g. a window matched "
                        "to its twin in several views (off by default: it costs one mapping)")
    p.add_argument("--ignore-watermarks", action="store_true",
                   help="read the database as COLMAP's mapper does with ignore_watermarks on: "
                        "its WATERMARK image pairs (only those) take no part and are copied "
                        "into OUT.db unchanged; the summary counts them (off by default, as "
                        "in COLMAP: every pair with inliers is used)")
    add_overwrite_and_memory_options(p, "OUT.db, its side files and --report")
    add_resolution_option(p, links_only=True)
    add_transport_option(p)


def _loop_tol(args) -> float | None:
    """The loop check's tolerance, or None when it is off (InputError on a bad value)."""
    from pipeline.errors import InputError
    from pipeline.matching.loops import DEFAULT_LOOP_TOL_DEG
    from pipeline.runs.clean_db import check_loop_tol

    if not args.loop_check:
        if args.loop_tol is not None:
            raise InputError(f"--loop-tol {args.loop_tol} without --loop-check: add "
                             f"--loop-check, or leave --loop-tol out")
        return None
    return check_loop_tol(DEFAULT_LOOP_TOL_DEG if args.loop_tol is None else args.loop_tol)


def run(args) -> int:
    from pipeline.budget import limit_gb
    from pipeline.outcome import exit_status, flag_result
    from pipeline.outputs import check_output_files
    from pipeline.runfolder import OutputFiles, write_json_atomic
    from pipeline.runs.clean_db import clean_database
    from pipeline.runs.cleaned import check_image_dir, side_paths, stale_recording

    limit_gb(args.max_memory_gb)
    loop_tol = _loop_tol(args)
    links_out, rrd_out = side_paths(args.out)
    check_output_files([("--out", args.out), ("--report", args.report),
                        ("OUT.links.csv", links_out)]
                       + ([] if args.no_rerun else [("OUT.rrd", rrd_out)]),
                       [("IN.db", args.database), ("--comm-graph", args.comm_graph)],
                       overwrite=args.overwrite)
    if not args.no_rerun:
        check_image_dir(args.image_dir, [])  # the folder; its images once the names are read
    # every output is written before any is put in place: an error leaves none of them
    with OutputFiles(replace=args.overwrite) as outputs:
        res = clean_database(args.database, args.out, args.comm_graph, args.max_memory_gb,
                             args.resolution, rerun=not args.no_rerun,
                             image_dir=args.image_dir, outputs=outputs,
                             baselines=args.baselines, loop_tol_deg=loop_tol,
                             fusion=args.fusion, ignore_watermarks=args.ignore_watermarks,
                             transport=args.transport)
        why = "the database holds no verified match between two images"
        if res.ignored_watermark_pairs and not res.links:
            why = (f"its {res.ignored_watermark_pairs} verified image pair(s) are all WATERMARK "
                   "pairs, which --ignore-watermarks leaves out and copies unchanged; drop "
                   "--ignore-watermarks to clean them")
        summary = flag_result(res.summary(), no_links_why=why)
        if args.report:
            write_json_atomic(outputs.path(args.report, "--report"), summary)
    if args.no_rerun and (stale := stale_recording(args.out)):
        print(stale, file=sys.stderr)
    b, a, cut, r = res.before, res.after, res.cut, res.resolution
    print(f"{res.images} images, {res.comm_edges} comm edges, {res.links} verified links")
    if res.ignored_watermark_pairs is not None:
        print(f"WATERMARK image pairs ignored (--ignore-watermarks): "
              f"{res.ignored_watermark_pairs}, copied unchanged")
    print(f"conflictive sets: {b['conflictive_sets']} before, {a['conflictive_sets']} after "
          f"({b['conflictive_features']} -> {a['conflictive_features']} conflictive features)")
    print(f"links cut: {cut['resolution']} by resolution in {r['iterations']} iteration(s) "
          f"({r['detection_rounds']} detection + {r['resolution_rounds']} resolution rounds, "
          f"{r['messages']} messages), {cut['not-one-to-one']} not one-to-one, "
          f"{cut['not-comm-edge']} outside the comm graph")
    if res.loop_check:
        lc = res.loop_check
        print(f"loop check: {lc['pairs_dropped']} of {lc['judged']} image pairs break their "
              f"rotation loops (tolerance {lc['tol_deg']:g}°), {lc['links_cut']} links cut; "
              f"{lc['pairs_without_triangle']} kept pairs on no loop")
        if lc["pairs_dropped"]:
            print("  fewer pairs can leave images below COLMAP's registration threshold: if "
                  "the mapper registers few, map with --Mapper.abs_pose_min_num_inliers 15")
    if res.fusion:
        print("\n".join(fusion_lines(res.fusion, cut["fusion-outlier"], res.images)))
    if res.baselines:
        from pipeline.evaluation.report import baselines_lines

        print("\n".join(baselines_lines(res.baselines, r["method"])))
    links_csv, rrd = side_paths(res.output)
    print(f"cleaned database written to {res.output}; what was cut: {links_csv}"
          + ("" if args.no_rerun else f", recording: {rrd}"))
    return exit_status(summary)


def fusion_lines(fu: dict, cut: int, images: int) -> list[str]:
    """What ``clean-db --fusion`` prints of its fusion section ``fu`` (``cut`` links cut as
    outliers, of a database of ``images`` images): the mapping it judged the tracks on, the
    largest of its models named as such (the images of the others are not fused)."""
    if not fu["enabled"]:
        return [f"fusion: not run, {fu['reason']}"]
    mp = fu["mapping"]
    models = int(mp.get("models", 1))
    out = [f"fusion: {cut} links cut as outliers of their tracks, on the poses of a COLMAP "
           f"mapping of the input ({fu['cameras']} of {images} images registered"
           + (f" in the largest of its {models} models" if models > 1 else "")
           + f", {mp['points']} points"
           + (f", {mp['mean_reprojection_error']:.2f} px)" if mp.get("mean_reprojection_error")
              is not None else ")")]
    if models > 1:
        out.append(f"  the images of the other models are not fused "
                   f"({len(fu['cameras_without_pose'])} without a pose here; see the report's "
                   "fusion.cameras_without_pose)")
    if cut:
        out.append("  fewer matches can leave images below COLMAP's registration threshold "
                   "where the views overlap little: if the mapper registers few, map with "
                   "--Mapper.abs_pose_min_num_inliers 15")
    return out
