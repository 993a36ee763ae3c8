"""``python -m pipeline clean-db IN.db --out OUT.db [--comm-graph FILE]``.

For COLMAP and hloc users: the verified matches of a database (its two-view geometries) are
made consistent by the distributed consistency stage (Aragüés et al., Sec. III detection and
Sec. IV Alg. 1 resolution, one robot per image), and a NEW database is written with the cut
links removed from the two-view geometries. Run COLMAP's mapper on OUT.db as usual.

Beside OUT.db it writes ``OUT.links.csv`` (every verified link, kept or deleted with its reason)
and ``OUT.rrd`` (:mod:`pipeline.cleaned`). Before the distributed stage, links the paper's
model cannot hold are cut too, each with its reason: ``not-one-to-one`` (a feature linked twice into the same other image, Assumption 2.2;
the later inlier of the pair is cut) and, with ``--comm-graph``, ``not-comm-edge`` (a link
between images that are not neighbours: those robots could not have matched).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.budget import DEFAULT_LIMIT_GB
from pipeline.commands.options import add_overwrite_and_memory_options, add_resolution_option
from pipeline.consistency import DEFAULT_RESOLUTION
from pipeline.errors import InputError

__all__ = ["CleanDbResult", "clean_database", "add_arguments", "run", "COLMAP_MAX_ERROR_PX"]

#: COLMAP's default two-view verification threshold (``max_error``, pixels)
COLMAP_MAX_ERROR_PX = 4.0


@dataclass
class CleanDbResult:
    """What ``clean-db`` did; ``summary()`` is printed and can be saved as JSON."""

    input: Path
    output: Path
    images: int
    comm_edges: int
    links: int
    before: dict
    after: dict
    cut: dict
    resolution: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {"input": str(self.input), "output": str(self.output), "images": self.images,
                "comm_edges": self.comm_edges, "links": self.links, "before": self.before,
                "after": self.after, "cut": self.cut, "resolution": self.resolution}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("database", metavar="IN.db", help="COLMAP database with two-view geometries "
                                                     "(made by COLMAP or hloc); never modified")
    p.add_argument("--out", required=True, metavar="OUT.db", help="the cleaned database to write")
    p.add_argument("--comm-graph", default=None, metavar="FILE",
                   help="communication graph: 'cam_i,cam_j' lines, 0-based indices of the images "
                        "in name order or image names (default: images sharing verified "
                        "matches are neighbours)")
    p.add_argument("--image-dir", default=None, metavar="DIR",
                   help="the images, to draw them in OUT.rrd (default: gray canvases)")
    p.add_argument("--no-rerun", action="store_true", help="do not write OUT.rrd")
    p.add_argument("--report", default=None, metavar="JSON",
                   help="also save the summary as JSON")
    add_overwrite_and_memory_options(p, "OUT.db / --report")
    add_resolution_option(p)


def clean_database(database: str | Path, out: str | Path,
                   comm_graph_file: str | Path | None = None,
                   max_memory_gb: float = DEFAULT_LIMIT_GB,
                   resolution: str = DEFAULT_RESOLUTION, *, rerun: bool = True,
                   image_dir: str | Path | None = None) -> CleanDbResult:
    """Read, make consistent, write a new database (see the module docstring).

    With ``resolution="evidence"`` a link's evidence is its Sampson error under the pair's
    stored fundamental matrix (:func:`pipeline.link_evidence.geometric_llr`, ``T`` =
    :data:`COLMAP_MAX_ERROR_PX`) plus the triangle support the robots compute; a database
    holds no Lowe ratios.

    Parameters
    ----------
    database : input COLMAP database
    out : output database (must differ from the input)
    comm_graph_file : optional comm-graph file (:func:`pipeline.commgraph.read_comm_graph`)
    rerun : also write ``OUT.rrd`` beside ``out`` (``OUT.links.csv`` is always written;
        :mod:`pipeline.cleaned`)
    image_dir : the images, drawn in the recording

    Returns
    -------
    CleanDbResult

    Raises
    ------
    InputError
        Missing/unreadable database, a database without two-view geometries, ``out`` equal to
        the input, a bad comm-graph file.
    """
    from pipeline import colmap
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.budget import check_detection_memory
    from pipeline.commgraph import links_off_graph, read_comm_graph
    from pipeline.outputs import require_input_file
    from pipeline.run import consistency_stage

    database, out = Path(database), Path(out)
    if out.resolve() == database.resolve():
        raise InputError(f"--out {str(out)!r} is the input database; the input is never "
                         f"modified, choose a new file")
    contents = colmap.read_database(database)
    links, m, n = contents.links, contents.features_per_camera, len(contents.names)
    reason = np.full(len(links), "", dtype=object)
    reason[contents.not_one_to_one] = "not-one-to-one"
    if comm_graph_file is not None:
        require_input_file(comm_graph_file, "--comm-graph")
        edges = read_comm_graph(comm_graph_file, contents.names)
        off_graph = links_off_graph(links, edges, n)
        reason[off_graph & (reason == "")] = "not-comm-edge"
    else:
        edges = None
    model_ok = reason == ""
    model_links = links.subset(model_ok)
    # the association graph the robots start from: one-to-one links on comm edges
    check_detection_memory(m, model_links, max_memory_gb)
    before = count_conflicts(AssociationGraph(m, model_links)).as_dict()
    evidence = dict(link_weight=_link_weight(contents, model_links),
                    keypoints=contents.keypoints) if resolution == "evidence" else None
    # the stage shows its own round counter on a long run (pipeline.progress.rounds_bar)
    result, _ = consistency_stage(m, edges, model_links, resolution=resolution, evidence=evidence)
    idx = np.flatnonzero(model_ok)
    reason[idx[result.deleted]] = "resolution"
    keep = reason == ""
    after = count_conflicts(AssociationGraph(m, links.subset(keep))).as_dict()
    colmap.write_cleaned_database(contents, out, keep)
    _side_outputs(contents, links, reason, idx, result, model_links, m, out, rerun, image_dir,
                  before, after)
    n_edges = len(edges) if edges is not None else \
        len(np.unique(model_links.cam_i * n + model_links.cam_j))
    stats = result.stats
    return CleanDbResult(
        input=database, output=out, images=n, comm_edges=n_edges, links=len(links),
        before=before, after=after,
        cut={k: int((reason == k).sum()) for k in ("not-one-to-one", "not-comm-edge", "resolution")},
        resolution={"method": stats.get("resolution"), **{k: stats.get(k) for k in (
            "iterations", "detection_rounds", "resolution_rounds", "messages", "bytes",
            "max_robot_memory_bytes")}})


def _link_weight(contents, links) -> np.ndarray:
    """Geometric log-likelihood ratio of each link from the pair's stored ``F``, ``(L,)``."""
    from pipeline.link_evidence import geometric_llr
    from pipeline.matching import sampson_error_px

    err = np.full(len(links), np.nan)
    n = len(contents.names)
    pair = links.cam_i * n + links.cam_j
    for key in np.unique(pair).tolist():
        i, j = divmod(key, n)
        F = contents.fundamental.get((i, j))
        if F is None:
            continue
        sel = pair == key
        err[sel] = sampson_error_px(F, contents.keypoints[i][links.feat_i[sel]],
                                    contents.keypoints[j][links.feat_j[sel]])
    return geometric_llr(err, pair, COLMAP_MAX_ERROR_PX)


def _side_outputs(contents, links, reason, idx, result, model_links, m, out, rerun, image_dir,
                  before, after) -> None:
    """``OUT.links.csv`` and ``OUT.rrd`` beside the cleaned database (:mod:`pipeline.cleaned`)."""
    from pipeline.cleaned import CleaningOutcome, write_side_outputs
    from pipeline.run import _conflictive_links

    rnd = np.full(len(links), -1, dtype=np.int64)
    it = np.full(len(links), -1, dtype=np.int64)
    rnd[idx], it[idx] = result.round, result.iteration
    conflictive = np.zeros(len(links), dtype=bool)
    conflictive[idx] = _conflictive_links(m, model_links)
    sizes = [(int(c.width), int(c.height)) if c is not None else (0, 0)
             for c in contents.cameras]
    md = (f"## clean-db {Path(contents.path).name}\n\n| | before | after |\n|---|---:|---:|\n"
          f"| Verified links | {len(links)} | {int((reason == '').sum())} |\n"
          f"| Conflictive sets | {before['conflictive_sets']} | {after['conflictive_sets']} |\n")
    write_side_outputs(CleaningOutcome(contents.names, sizes, contents.keypoints, links,
                                       reason.astype(str), rnd, it, conflictive),
                       out, rerun=rerun, image_dir=image_dir, report_markdown=md)


def run(args) -> int:
    from pipeline.cleaned import side_paths
    from pipeline.outcome import exit_status, flag_result
    from pipeline.outputs import check_output_files

    links_out, rrd_out = side_paths(args.out)
    check_output_files([("--out", args.out), ("--report", args.report),
                        ("OUT.links.csv", links_out)]
                       + ([] if args.no_rerun else [("OUT.rrd", rrd_out)]),
                       [("IN.db", args.database), ("--comm-graph", args.comm_graph)],
                       overwrite=args.overwrite)
    res = clean_database(args.database, args.out, args.comm_graph, args.max_memory_gb,
                         args.resolution, rerun=not args.no_rerun, image_dir=args.image_dir)
    b, a, cut, r = res.before, res.after, res.cut, res.resolution
    print(f"{res.images} images, {res.comm_edges} comm edges, {res.links} verified links")
    print(f"conflictive sets: {b['conflictive_sets']} before, {a['conflictive_sets']} after "
          f"({b['conflictive_features']} -> {a['conflictive_features']} conflictive features)")
    print(f"links cut: {cut['resolution']} by resolution in {r['iterations']} iteration(s) "
          f"({r['detection_rounds']} detection + {r['resolution_rounds']} resolution rounds, "
          f"{r['messages']} messages), {cut['not-one-to-one']} not one-to-one, "
          f"{cut['not-comm-edge']} outside the comm graph")
    links_csv, rrd = side_paths(res.output)
    print(f"cleaned database written to {res.output}; what was cut: {links_csv}"
          + ("" if args.no_rerun else f", recording: {rrd}"))
    summary = flag_result(res.summary())
    if args.report:
        from pipeline.runfolder import write_json_atomic

        write_json_atomic(args.report, summary)
    return exit_status(summary)
