"""``python -m pipeline resolve --links IN.csv --out OUT.csv [--comm-graph EDGES.csv]``.

A user's own links made conflict-free by the distributed consistency stage; the job and
what it writes are described in :mod:`pipeline.runs.resolve`. This module parses the
options and prints the summary.
"""

from __future__ import annotations

import argparse

from pipeline.commands.options import (
    add_overwrite_and_memory_options,
    add_resolution_option,
    add_transport_option,
)
from pipeline.faults import (
    add_fault_arguments,
    check_faults_for_transport,
    faults_from_args,
)

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--links", required=True, metavar="IN.csv",
                   help="links, one per row: cam_i,feat_i,cam_j,feat_j[,quality] (0-based ids, "
                        "header optional), or a run-output links.csv (e.g. this command's own "
                        "output: deleted rows stay deleted); never modified")
    p.add_argument("--out", required=True, metavar="OUT.csv",
                   help="links.csv to write: cam_i,feat_i,cam_j,feat_j,status,reason,round,truth"
                        "[,quality] (the input's quality, if it has one)")
    p.add_argument("--comm-graph", default=None, metavar="EDGES.csv",
                   help="communication graph, rows cam_i,cam_j (default: cameras sharing a "
                        "link are neighbours)")
    p.add_argument("--report", default=None, metavar="JSON", help="also save the summary as JSON")
    p.add_argument("--baselines", action="store_true",
                   help="also run the centralized baselines on the same links (spectral "
                        "synchronization, a CLEAR-style method, union-find dropping conflictive "
                        "sets, ...), for comparison: a line each and the summary's baselines")
    add_overwrite_and_memory_options(p, "--out / --report")
    add_resolution_option(p, links_only=True, faults=True)
    add_transport_option(p)
    add_fault_arguments(p)


def run(args) -> int:
    from pipeline.budget import limit_gb
    from pipeline.consistency.rules import get_rule
    from pipeline.outcome import exit_status, flag_result
    from pipeline.outputs import check_output_files
    from pipeline.runfolder import OutputFiles, write_json_atomic
    from pipeline.runs.resolve import resolve_file

    limit_gb(args.max_memory_gb)
    check_output_files([("--out", args.out), ("--report", args.report)],
                       [("--links", args.links), ("--comm-graph", args.comm_graph)],
                       overwrite=args.overwrite)
    faults = faults_from_args(args)
    check_faults_for_transport(faults, args.transport)  # the rule's warning: resolve_file's
    # every output is written before any is put in place: an error leaves none of them
    with OutputFiles(replace=args.overwrite) as outputs:
        s = flag_result(resolve_file(args.links, args.out, args.comm_graph,
                                     faults, args.max_memory_gb,
                                     resolution=args.resolution, transport=args.transport,
                                     outputs=outputs, baselines=args.baselines),
                        no_links_why="the links file holds no link row, or only rows "
                                     "already deleted")
        if args.report:
            write_json_atomic(outputs.path(args.report, "--report"), s)
    b, a, r = s["before"], s["after"], s["resolution"]
    print(f"{s['cameras']} cameras, {s['comm_edges']} comm edges, {s['links']} links")
    print(f"conflictive sets: {b['conflictive_sets']} before, {a['conflictive_sets']} after "
          f"({b['conflictive_features']} -> {a['conflictive_features']} conflictive features)")
    cut = get_rule(s["resolution_method"]).summary.format(**s["deleted_by_case"])
    print(f"deleted: {s['deleted']} links {cut} in {r['iterations']} iteration(s)")
    closing = f" + {r['closing_rounds']} closing" if "closing_rounds" in r else ""
    print(f"rounds: {r['detection_rounds']} detection + {r['resolution_rounds']} resolution"
          f"{closing}; "
          f"{r['messages']} messages, {r['bytes']} bytes, max {r['max_robot_memory_bytes']} "
          "bytes per robot")
    if "faults" in s:
        f = s["faults"]
        crashed = ", ".join(f"robot {k} at round {v}" for k, v in
                            sorted(f["crashed"].items(), key=lambda kv: int(kv[0]))) or "none"
        extra = (f"; {f['extra_rounds']:+d} rounds, {f['extra_messages']:+d} messages vs the "
                 "same rule fault-free" if "extra_rounds" in f else "")
        print(f"faults: {f['messages_dropped']} messages dropped, crashed: {crashed}, "
              f"{f['links_cut_robot_lost']} links cut robot-lost; {f['retransmissions']} "
              f"retransmissions{extra}")
    if "baselines" in s:
        from pipeline.evaluation.report import baselines_lines

        print("\n".join(baselines_lines(s["baselines"], s["resolution_method"])))
    print(f"written: {s['output']}" + (f", {args.report}" if args.report else ""))
    return exit_status(s)
