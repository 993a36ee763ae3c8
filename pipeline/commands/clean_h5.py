"""``formation-match clean-h5 --features features.h5 --matches matches.h5 --out OUT.h5``.

hloc's matches made consistent; the job and what it writes are described in
:mod:`pipeline.runs.clean_h5`. This module parses the options and prints the summary.
"""

from __future__ import annotations

import argparse
import sys

from pipeline.commands.options import (
    add_overwrite_and_memory_options,
    add_resolution_option,
    add_transport_option,
)
from pipeline.errors import InputError

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--features", required=True, metavar="features.h5",
                   help="hloc features file (groups per image with 'keypoints'); never modified")
    p.add_argument("--matches", required=True, metavar="matches.h5",
                   help="hloc matches file (groups per pair with 'matches0'); never modified")
    p.add_argument("--pairs", default=None, metavar="pairs.txt",
                   help="hloc pairs file ('name0 name1' per line): the pairs to read and the "
                        "communication graph (default: every pair stored in matches.h5)")
    p.add_argument("--out", required=True, metavar="OUT.h5",
                   help="cleaned matches file to write, in hloc's format; OUT.links.csv and "
                        "OUT.rrd are written beside it")
    p.add_argument("--image-dir", default=None, metavar="DIR",
                   help="the images, to draw them in OUT.rrd (default: gray canvases)")
    p.add_argument("--no-rerun", action="store_true", help="do not write OUT.rrd")
    p.add_argument("--report", default=None, metavar="JSON", help="also save the summary as JSON")
    p.add_argument("--baselines", action="store_true",
                   help="also run the centralized baselines on the same matches (spectral "
                        "synchronization, a CLEAR-style method, union-find dropping conflictive "
                        "sets, ...), for comparison: a line each and the summary's baselines")
    add_overwrite_and_memory_options(p, "OUT.h5, its side files and --report")
    add_resolution_option(p, links_only=True)
    add_transport_option(p)


def run(args) -> int:
    from pipeline.budget import limit_gb
    from pipeline.outcome import exit_status, flag_result
    from pipeline.outputs import check_output_files
    from pipeline.runfolder import OutputFiles, write_json_atomic
    from pipeline.runs.clean_h5 import clean_h5
    from pipeline.runs.cleaned import check_image_dir, side_paths, stale_recording

    limit_gb(args.max_memory_gb)
    if not args.out:
        raise InputError("--out '': give the name of the cleaned matches file to write, e.g. "
                         "matches-clean.h5")
    if not args.no_rerun:
        check_image_dir(args.image_dir, [])  # the folder; its images once the names are read
    links_out, rrd_out = side_paths(args.out)
    check_output_files([("--out", args.out), ("--report", args.report),
                        ("OUT.links.csv", links_out)]
                       + ([] if args.no_rerun else [("OUT.rrd", rrd_out)]),
                       [("--features", args.features), ("--matches", args.matches),
                        ("--pairs", args.pairs)],
                       overwrite=args.overwrite)
    # every output is written before any is put in place: an error leaves none of them
    with OutputFiles(replace=args.overwrite) as outputs:
        s = flag_result(clean_h5(args.features, args.matches, args.out, args.pairs,
                                 rerun=not args.no_rerun, image_dir=args.image_dir,
                                 outputs=outputs, max_memory_gb=args.max_memory_gb,
                                 baselines=args.baselines, resolution=args.resolution,
                                 transport=args.transport),
                        no_links_why="matches.h5 holds no match between two images of the "
                                     "pairs read")
        if args.report:
            write_json_atomic(outputs.path(args.report, "--report"), s)
    if args.no_rerun and (stale := stale_recording(args.out)):
        print(stale, file=sys.stderr)
    b, a, cut, r = s["before"], s["after"], s["cut"], s["resolution"]
    print(f"{s['images']} images, {s['comm_edges']} image pairs, {s['links']} matches")
    print(f"conflictive sets: {b['conflictive_sets']} before, {a['conflictive_sets']} after "
          f"({b['conflictive_features']} -> {a['conflictive_features']} conflictive features)")
    print(f"matches cut: {cut['resolution']} by resolution in {r['iterations']} iteration(s), "
          f"{cut['not-one-to-one']} not one-to-one")
    if "baselines" in s:
        from pipeline.evaluation.report import baselines_lines

        print("\n".join(baselines_lines(s["baselines"], r["resolution"])))
    print("written: " + ", ".join(s["written"] + ([args.report] if args.report else [])))
    return exit_status(s)
