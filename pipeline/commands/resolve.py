"""``python -m pipeline resolve --links IN.csv --out OUT.csv [--comm-graph EDGES.csv]``.

Makes a user's own links conflict-free with the distributed consistency stage (Aragüés et
al., Sec. III detection and Sec. IV Alg. 1 resolution, one robot per camera) and writes the
run-output ``links.csv`` (docs/DESIGN.md): every input row once, ``status`` ``kept`` or
``deleted``, ``reason`` ``resolution`` for a cut link, the resolution ``round`` that cut it,
``truth`` empty (unknown). Input rows are ``cam_i,feat_i,cam_j,feat_j[,quality]``; without
``--comm-graph``, cameras that share a link are neighbours. A run-output ``links.csv`` (this
command's own output, or a run folder's) is accepted as input too: its deleted rows are
written back unchanged and its kept rows are made consistent.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from pipeline.budget import DEFAULT_LIMIT_GB
from pipeline.commands.options import add_overwrite_and_memory_options, add_resolution_option
from pipeline.consistency import DEFAULT_RESOLUTION
from pipeline.errors import InputError
from pipeline.faults import FaultConfig, add_fault_arguments, faults_from_args
from pipeline.team import add_transport_argument, resolution_for_transport

__all__ = ["add_arguments", "run", "resolve_file"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--links", required=True, metavar="IN.csv",
                   help="links, one per row: cam_i,feat_i,cam_j,feat_j[,quality] (0-based ids, "
                        "header optional), or a run-output links.csv (e.g. this command's own "
                        "output: deleted rows stay deleted); never modified")
    p.add_argument("--out", required=True, metavar="OUT.csv",
                   help="links.csv to write: cam_i,feat_i,cam_j,feat_j,status,reason,round,truth")
    p.add_argument("--comm-graph", default=None, metavar="EDGES.csv",
                   help="communication graph, rows cam_i,cam_j (default: cameras sharing a "
                        "link are neighbours)")
    p.add_argument("--report", default=None, metavar="JSON", help="also save the summary as JSON")
    add_overwrite_and_memory_options(p, "--out / --report")
    add_resolution_option(p)
    add_transport_argument(p)
    add_fault_arguments(p)


def resolve_file(links_csv: str | Path, out_csv: str | Path,
                 comm_graph_csv: str | Path | None = None,
                 faults: FaultConfig | None = None,
                 max_memory_gb: float = DEFAULT_LIMIT_GB, resolution: str = DEFAULT_RESOLUTION,
                 transport: str = "sim") -> dict:
    """Read, resolve, write; return the summary dict (with a ``faults`` section if any).

    ``resolution``: ``paper`` (Alg. 1) or ``evidence``; the evidence of a link here is its
    ``quality`` column read as ``1 − Lowe ratio`` (and the triangle support the robots
    compute), as a links file carries no keypoints or geometry.

    Raises
    ------
    InputError
        Bad input rows (see :func:`pipeline.linkscsv.read_links_csv`), a bad comm-graph file,
        ``out`` equal to the input, or a link between cameras that are not neighbours in the
        given comm graph (naming its row).
    """
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.budget import check_detection_memory
    from pipeline.commgraph import links_off_graph, read_comm_graph
    from pipeline.compact import compact_ids, fault_section_in_ids, faults_in_layout
    from pipeline.linkscsv import read_links_csv, write_links_csv
    from pipeline.run import consistency_stage, ledger_from_consistency
    from pipeline.types import LinkLedger

    links_csv, out_csv = Path(links_csv), Path(out_csv)
    if out_csv.exists() and out_csv.resolve() == links_csv.resolve():
        raise InputError(f"--out {str(out_csv)!r} is the input file; the input is never "
                         "modified, choose a new file")
    lf = read_links_csv(links_csv)
    links = lf.links
    edges = None
    n_cams = None
    if comm_graph_csv is not None:
        edges = read_comm_graph(comm_graph_csv)
        n_cams = int(edges.max(initial=-1)) + 1
    # ids as given, or made compact when sparse (pipeline.compact): memory follows the links
    ids = compact_ids(links, edges, n_cameras=n_cams)
    n = int(ids.cameras.max(initial=-1)) + 1
    if edges is not None and len(links):
        off = links_off_graph(links, edges, n)
        if off.any():
            k = int(np.flatnonzero(off)[0])
            raise InputError(
                f"{links_csv}:{lf.line[k]}: link ({links.cam_i[k]},{links.feat_i[k]})-"
                f"({links.cam_j[k]},{links.feat_j[k]}) joins cameras {links.cam_i[k]} and "
                f"{links.cam_j[k]}, which are not neighbours in {comm_graph_csv}; add the edge "
                "or remove the link")
    all_links = links
    # a run-output links.csv (e.g. our own output): its deleted rows stay deleted with their
    # reason and round; its kept rows are the links to make consistent
    active = lf.status == "kept" if lf.status is not None else np.ones(len(links), dtype=bool)
    if not active.all():
        links = all_links.subset(active)
        ids = compact_ids(links, edges, n_cameras=n_cams)
    m, run_links, run_edges = ids.features_per_camera, ids.links, ids.edges
    check_detection_memory(m, run_links, max_memory_gb)
    before = count_conflicts(AssociationGraph(m, run_links)).as_dict()
    if transport == "zenoh":
        res, fault_section = _resolve_over_zenoh(m, run_edges, run_links, faults, resolution)
    else:
        # the stage shows its own round counter on a long run (pipeline.progress.rounds_bar)
        res, fault_section = consistency_stage(
            m, run_edges, run_links, None if faults is None else faults_in_layout(faults, ids),
            resolution=resolution)
    after = count_conflicts(AssociationGraph(m, res.kept())).as_dict()
    ledger = ledger_from_consistency(res)
    ledger.links = links  # the ids as given (the stage may have run on compact ones)
    if lf.status is not None:
        # rows the input file had already deleted stay deleted with their reason and round
        full = LinkLedger.all_kept(all_links)
        idx = np.flatnonzero(active)
        for name in ("status", "reason", "round", "iteration", "case"):
            getattr(full, name)[idx] = getattr(ledger, name)
        old = np.flatnonzero(~active)
        full.status[old], full.reason[old], full.round[old] = "deleted", lf.reason[old], lf.round[old]
        ledger = full
    write_links_csv(out_csv, ledger)
    st = res.stats
    summary = {
        "input": str(links_csv), "output": str(out_csv), "cameras": int(m.size),
        "comm_edges": int(len(edges)) if edges is not None else
        int(np.unique(links.cam_i * n + links.cam_j).size),
        "links": len(all_links), "deleted": int(res.deleted.sum()),
        "previously_deleted": int((~active).sum()),
        "resolution_method": res.stats["resolution"],
        "deleted_by_case": {c: int((res.case == c).sum()) for c in
                            ("b", "c", "evidence") if c != "evidence" or resolution == "evidence"},
        "before": before, "after": after,
        "resolution": {k: st[k] for k in ("iterations", "detection_rounds", "resolution_rounds",
                                          "closing_rounds", "messages", "bytes",
                                          "max_robot_memory_bytes") if k in st},
    }
    if fault_section is not None:
        summary["faults"] = fault_section_in_ids(fault_section, ids)
    if transport == "zenoh":
        summary["team"] = res.stats["team"]
    return summary


def _resolve_over_zenoh(m, edges, links, faults, resolution=DEFAULT_RESOLUTION):
    """The consistency stage as one robot process per camera over Zenoh.

    The links to make consistent (kept rows, compact ids, with their quality: the evidence
    of the evidence rule) go to a file in a temporary team folder; each robot reads its own
    rows of it (:func:`pipeline.teamrun.resolve_conflicts_team`).
    Returns ``(ConsistencyResult, faults section or None)``.
    """
    import tempfile

    from pipeline.commgraph import comm_edges_for
    from pipeline.faults import fault_report
    from pipeline.teamrun import resolve_conflicts_team, team_options

    with tempfile.TemporaryDirectory(prefix="resolve-team-") as work:
        path = Path(work) / "links.csv"
        path.write_text("cam_i,feat_i,cam_j,feat_j,quality\n" + "".join(
            f"{a},{b},{c},{d},{float(q)!r}\n" for a, b, c, d, q in zip(
                links.cam_i.tolist(), links.feat_i.tolist(), links.cam_j.tolist(),
                links.feat_j.tolist(), links.quality.tolist(), strict=True)))
        res = resolve_conflicts_team(path, m, comm_edges_for(m, links, edges),
                                     team_options(faults=faults, resolution=resolution),
                                     workdir=work)
    fault_section = None
    if (faults is not None and faults.any) or res.stats["faults"]["robots_lost"]:
        fault_section = fault_report(faults or FaultConfig(), res)
    return res, fault_section


def run(args) -> int:
    from pipeline.outcome import exit_status, flag_result
    from pipeline.outputs import check_output_files

    check_output_files([("--out", args.out), ("--report", args.report)],
                       [("--links", args.links), ("--comm-graph", args.comm_graph)],
                       overwrite=args.overwrite)
    s = flag_result(resolve_file(args.links, args.out, args.comm_graph, faults_from_args(args),
                                  args.max_memory_gb, resolution=resolution_for_transport(args),
                                  transport=args.transport))
    b, a, r = s["before"], s["after"], s["resolution"]
    print(f"{s['cameras']} cameras, {s['comm_edges']} comm edges, {s['links']} links")
    print(f"conflictive sets: {b['conflictive_sets']} before, {a['conflictive_sets']} after "
          f"({b['conflictive_features']} -> {a['conflictive_features']} conflictive features)")
    if s["resolution_method"] == "paper":
        print(f"deleted: {s['deleted']} links (case b: {s['deleted_by_case']['b']}, case c: "
              f"{s['deleted_by_case']['c']}) in {r['iterations']} iteration(s)")
    else:
        print(f"deleted: {s['deleted']} links by the evidence rule in {r['iterations']} "
              "iteration(s)")
    closing = f" + {r['closing_rounds']} closing" if "closing_rounds" in r else ""
    print(f"rounds: {r['detection_rounds']} detection + {r['resolution_rounds']} resolution"
          f"{closing}; "
          f"{r['messages']} messages, {r['bytes']} bytes, max {r['max_robot_memory_bytes']} "
          "bytes per robot")
    if "faults" in s:
        f = s["faults"]
        print(f"faults: {f['messages_dropped']} messages dropped, crashed {f['crashed'] or 'none'}, "
              f"{f['links_cut_robot_lost']} links cut robot-lost; {f['retransmissions']} "
              f"retransmissions; +{f.get('extra_rounds', '?')} rounds, "
              f"+{f.get('extra_messages', '?')} messages "
              "vs fault-free")
    print(f"written: {s['output']}")
    if args.report:
        from pipeline.runfolder import write_json_atomic

        write_json_atomic(args.report, s)
    return exit_status(s)
