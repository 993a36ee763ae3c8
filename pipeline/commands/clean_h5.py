"""``formation-match clean-h5 --features features.h5 --matches matches.h5 --out OUT.h5``.

For hloc users: the matches of hloc's ``matches.h5`` are made consistent by the distributed
consistency stage (Aragüés et al., Sec. III detection and Sec. IV Alg. 1 resolution, one robot
per image), and a NEW ``matches.h5`` is written in hloc's format with the cut matches removed
(``matches0 = -1``), ready for ``hloc.reconstruction.main(..., matches=OUT.h5)``. The file
layout is described in :mod:`pipeline.hloc`.

The communication graph is the list of image pairs: ``--pairs pairs.txt`` (hloc's pairs file;
only those pairs are read), else every pair stored in ``matches.h5``. Before the distributed
stage, matches the paper's model cannot hold are cut with reason ``not-one-to-one`` (a
keypoint matched twice into the same other image, Assumption 2.2). Beside OUT.h5 it writes
``OUT.links.csv`` and ``OUT.rrd`` (:mod:`pipeline.cleaned`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from pipeline.errors import InputError

__all__ = ["clean_h5", "add_arguments", "run"]


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
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUT.h5, its side files and --report if they exist "
                        "(default: refuse)")


def clean_h5(features: str | Path, matches: str | Path, out: str | Path,
             pairs: str | Path | None = None, *, rerun: bool = True,
             image_dir: str | Path | None = None) -> dict:
    """Read hloc's files, make the matches consistent, write OUT.h5 and its side outputs.

    Returns
    -------
    dict — the summary printed by the command (counts before/after, links cut by reason,
    resolution figures, files written)

    Raises
    ------
    InputError
        Bad input files (see :func:`pipeline.hloc.read_h5`), ``out`` equal to the matches file
        (the command checks every output against every input first,
        :func:`pipeline.outputs.check_output_files`).
    """
    from pipeline import hloc
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.cleaned import CleaningOutcome, write_side_outputs
    from pipeline.run import _conflictive_links, consistency_stage

    out = Path(out)
    contents = hloc.read_h5(features, matches, pairs)
    links, m, n = contents.links, contents.features_per_camera, len(contents.names)
    cam = {name: k for k, name in enumerate(contents.names)}
    if pairs is not None:
        pair_list = hloc.read_pairs(pairs, set(contents.names))
        edges = np.unique(np.sort(np.array([[cam[a], cam[b]] for a, b in pair_list]), axis=1),
                          axis=0)
    else:
        edges = np.unique(np.stack([links.cam_i, links.cam_j], axis=1), axis=0)
    reason = np.full(len(links), "", dtype=object)
    reason[contents.not_one_to_one] = "not-one-to-one"
    ok = reason == ""
    model_links = links.subset(ok)
    before = count_conflicts(AssociationGraph(m, model_links)).as_dict()
    result, _ = consistency_stage(m, edges, model_links, resolution="paper")
    idx = np.flatnonzero(ok)
    reason[idx[result.deleted]] = "resolution"
    rnd = np.full(len(links), -1, dtype=np.int64)
    it = np.full(len(links), -1, dtype=np.int64)
    rnd[idx] = result.round
    it[idx] = result.iteration
    conflictive = np.zeros(len(links), dtype=bool)
    conflictive[idx] = _conflictive_links(m, model_links)
    keep = reason == ""
    after = count_conflicts(AssociationGraph(m, links.subset(keep))).as_dict()
    hloc.write_cleaned_matches(contents, out, keep)
    cut = {k: int((reason == k).sum()) for k in ("not-one-to-one", "resolution")}
    md = (f"## clean-h5 {Path(matches).name}\n\n| | before | after |\n|---|---:|---:|\n"
          f"| Matches | {len(links)} | {int(keep.sum())} |\n"
          f"| Conflictive sets | {before['conflictive_sets']} | {after['conflictive_sets']} |\n"
          f"| Cut not one-to-one | | {cut['not-one-to-one']} |\n"
          f"| Cut by resolution | | {cut['resolution']} |\n")
    outcome = CleaningOutcome(
        names=contents.names, sizes=[_size_of(k) for k in contents.keypoints],
        keypoints=contents.keypoints, links=links, reason=reason.astype(str), round=rnd,
        iteration=it, conflictive_before=conflictive)
    written = write_side_outputs(outcome, out, rerun=rerun, image_dir=image_dir,
                                 report_markdown=md)
    st = result.stats
    return {"features": str(features), "matches": str(matches), "output": str(out),
            "written": [str(out)] + [str(p) for p in written], "images": n,
            "comm_edges": int(len(edges)), "links": int(len(links)), "before": before,
            "after": after, "cut": cut,
            "resolution": {k: st.get(k) for k in ("iterations", "detection_rounds",
                                                  "resolution_rounds", "messages", "bytes")}}


#: largest side of a gray canvas drawn for an image (keypoints beyond it are off the canvas)
MAX_CANVAS_SIDE = 8192


def _size_of(keypoints: np.ndarray) -> tuple[int, int]:
    """A canvas that holds every keypoint (hloc's features.h5 may omit ``image_size``), at most
    :data:`MAX_CANVAS_SIDE` on a side."""
    if len(keypoints) == 0:
        return (64, 64)
    w, h = np.clip(np.ceil(keypoints.max(axis=0) + 1), 16, MAX_CANVAS_SIDE).astype(int)
    return (int(w), int(h))


def run(args) -> int:
    from pipeline.cleaned import side_paths
    from pipeline.outcome import exit_status, flag_result
    from pipeline.outputs import check_output_files

    if not args.out:
        raise InputError("--out '': give the name of the cleaned matches file to write, e.g. "
                         "matches-clean.h5")
    if args.image_dir is not None and not Path(args.image_dir).is_dir():
        raise InputError(f"--image-dir {args.image_dir!r} is not a folder; give the folder of "
                         "the images (or leave it out: gray canvases are drawn)")
    links_out, rrd_out = side_paths(args.out)
    check_output_files([("--out", args.out), ("--report", args.report),
                        ("OUT.links.csv", links_out)]
                       + ([] if args.no_rerun else [("OUT.rrd", rrd_out)]),
                       [("--features", args.features), ("--matches", args.matches),
                        ("--pairs", args.pairs)],
                       overwrite=args.overwrite)
    s = flag_result(clean_h5(args.features, args.matches, args.out, args.pairs,
                             rerun=not args.no_rerun, image_dir=args.image_dir))
    b, a, cut, r = s["before"], s["after"], s["cut"], s["resolution"]
    print(f"{s['images']} images, {s['comm_edges']} image pairs, {s['links']} matches")
    print(f"conflictive sets: {b['conflictive_sets']} before, {a['conflictive_sets']} after "
          f"({b['conflictive_features']} -> {a['conflictive_features']} conflictive features)")
    print(f"matches cut: {cut['resolution']} by resolution in {r['iterations']} iteration(s), "
          f"{cut['not-one-to-one']} not one-to-one")
    print("written: " + ", ".join(s["written"]))
    if args.report:
        from pipeline.runfolder import write_json_atomic

        write_json_atomic(args.report, s)
    return exit_status(s)
