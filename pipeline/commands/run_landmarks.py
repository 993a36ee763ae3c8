"""``python -m pipeline run-landmarks DIR --graph KIND``: labelled-landmark benchmarks.

The job (stages, defaults, scoring, outputs) is described in
:mod:`pipeline.runs.landmarks`. This module parses the options and prints the report.
"""

from __future__ import annotations

import argparse

from pipeline.commands.options import add_memory_option, add_transport_option
from pipeline.errors import InputError
from pipeline.runs.landmarks import (
    REFINEMENTS,
    LandmarksConfig,
    default_refinement,
    landmarks_markdown,
    run_landmarks,
)

__all__ = ["add_arguments", "config_from_args", "run"]


def _ratio(text: str) -> float | None:
    if text.lower() == "none":
        return None
    try:
        r = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number in (0, 1] or 'none'") from None
    if not 0 < r <= 1:
        raise argparse.ArgumentTypeError(f"{text}: expected a number in (0, 1] or 'none'")
    return r


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("directory", metavar="DIR",
                   help="folder of images, each with NAME.txt (K rows 'x y') or NAME.mat "
                        "(pts_coord 2 x K): the same K labelled landmarks in the same order")
    p.add_argument("--graph", default="complete",
                   metavar="line|ring|ring2|complete|seq:K|FILE",
                   help="communication graph over the images in name order (default complete): "
                        "line, ring, ring2 (ring + 2-hop chords), ring+triangles, complete, "
                        "seq:K (each image with the K nearest in name order) or a file of "
                        "'cam_i,cam_j' lines (image names, or indices in the folder's name "
                        "order, --frames or not: with --frames every edge joins kept images)")
    p.add_argument("--frames", type=int, default=None, metavar="N",
                   help="use N images at a fixed stride floor(n/N) from the first (default all)")
    p.add_argument("--descriptors", default="auto", choices=("auto", "given", "sift"),
                   help="given: one NAME.scf per image (rows = landmarks; histograms compared "
                        "by chi-square); sift: SIFT at the keypoints (L2); auto (default): "
                        "given when the folder holds .scf files, else sift")
    p.add_argument("--ratio", type=_ratio, default=None, metavar="R|none",
                   help="gate of the Hungarian matches: keep a pair if its distance is at most "
                        "R times the nearest alternative in its row or column (Lowe's ratio, "
                        "e.g. 0.8); none (default) keeps the whole assignment")
    p.add_argument("--geometry", default="epipolar", choices=("epipolar", "none"),
                   help="epipolar (default): after the assignment, fit a fundamental matrix by "
                        "RANSAC and assign again within the epipolar band (guided matching); "
                        "none: descriptors only (the input CLEAR is benchmarked on)")
    p.add_argument("--epipolar-px", type=float, default=None, metavar="PX",
                   help="Sampson error bound of --geometry epipolar (default 3 px: hand-labelled "
                        "positions)")
    p.add_argument("--refine", default=None, choices=REFINEMENTS,
                   help="votes: robots refine their matches by two-hop votes through common "
                        "neighbours until a fixed point; none: use the matches as they are "
                        "(default: none for a rule that weighs the links' cycles itself, sync "
                        "and evidence; votes for paper and paper-labels)")
    p.add_argument("--vote-iterations", type=int, default=None, metavar="N",
                   help="cap on the vote iterations (two rounds each; default 10)")
    from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION, RULES

    p.add_argument("--resolution", default=DEFAULT_LINKS_RESOLUTION, choices=tuple(RULES),
                   help="resolution of the distributed stage: "
                        + "; ".join(f"{k}: {rule.title}" for k, rule in RULES.items())
                        + f" (default {DEFAULT_LINKS_RESOLUTION})")
    p.add_argument("--no-baselines", action="store_true",
                   help="skip the centralized baselines")
    p.add_argument("--out", default=None,
                   help="run folder (default runs/landmarks-<DIR name>[-fN]-<graph>; a graph "
                        "file by its name without suffix)")
    add_memory_option(p)
    add_transport_option(p)


def _refuse_unused_options(args) -> None:
    """InputError when ``--epipolar-px`` or ``--vote-iterations`` is given to a run whose
    matching or refinement does not read it (it would be ignored without a word); a bad
    value is named first (:func:`pipeline.runs.landmarks.run_landmarks`)."""
    px, votes = args.epipolar_px, args.vote_iterations
    if (px is not None and not 0 < px < float("inf")) or (votes is not None and votes < 1):
        return
    if args.epipolar_px is not None and args.geometry != "epipolar":
        raise InputError(f"--epipolar-px applies to --geometry epipolar only (this run has "
                         f"--geometry {args.geometry}); drop it")
    refine = args.refine or default_refinement(args.resolution)
    if args.vote_iterations is not None and refine != "votes":
        why = "" if args.refine else f", the default of --resolution {args.resolution}"
        raise InputError(f"--vote-iterations applies to --refine votes only (this run refines "
                         f"by {refine}{why}); add --refine votes or drop it")


def config_from_args(args) -> LandmarksConfig:
    from pipeline.budget import limit_gb

    _refuse_unused_options(args)
    limit_gb(args.max_memory_gb)  # a bad limit is refused before the matching
    given = {k: v for k, v in (("epipolar_px", args.epipolar_px),
                               ("vote_iterations", args.vote_iterations)) if v is not None}
    return LandmarksConfig(directory=args.directory, graph=args.graph, frames=args.frames,
                           descriptors=args.descriptors, ratio=args.ratio,
                           geometry=args.geometry, refine=args.refine,
                           resolution=args.resolution, baselines=not args.no_baselines,
                           out=args.out, max_memory_gb=args.max_memory_gb,
                           transport=args.transport, **given)


def run(args) -> int:
    from pipeline.outcome import exit_status
    from pipeline.runfolder import claim_run_folder

    config = config_from_args(args)
    if config.out is not None and not config.out:
        raise InputError("--out '': give the name of the run folder, e.g. runs/hotel")
    if not 0 < config.epipolar_px < float("inf"):
        raise InputError(f"--epipolar-px {config.epipolar_px}: expected a positive, finite "
                         "number of pixels")
    with claim_run_folder(config.out_dir(), inputs=[("DIR", config.directory)]):
        out, report = run_landmarks(config)
    print(landmarks_markdown(report))
    print(f"run written to {out}/ (report.json, links.csv)")
    return exit_status(report)
