"""The ``resolve`` job (:mod:`pipeline.commands.resolve` parses its options): a links file in,
a conflict-free ``links.csv`` out.

Makes a user's own links conflict-free with the distributed consistency stage (Aragüés et
al., Sec. III detection and Sec. IV Alg. 1 resolution, one robot per camera) and writes the
run-output ``links.csv`` (docs/DESIGN.md): every input row once, ``status`` ``kept`` or
``deleted``, ``reason`` ``resolution`` for a cut link, the resolution ``round`` that cut it,
``truth`` empty (unknown), and where the input has a quality column, each link's quality in a
last column ``quality``. Input rows are ``cam_i,feat_i,cam_j,feat_j[,quality]``; without
``--comm-graph``, cameras that share a link are neighbours. A run-output ``links.csv`` (this
command's own output, or a run folder's) is accepted as input too: its deleted rows are
written back unchanged and its kept rows are made consistent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.budget import DEFAULT_LIMIT_GB
from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION
from pipeline.errors import InputError
from pipeline.faults import FaultConfig

__all__ = ["resolve_file"]


def resolve_file(links_csv: str | Path, out_csv: str | Path,
                 comm_graph_csv: str | Path | None = None,
                 faults: FaultConfig | None = None,
                 max_memory_gb: float = DEFAULT_LIMIT_GB, resolution: str = DEFAULT_LINKS_RESOLUTION,
                 transport: str = "sim", outputs=None, baselines: bool = False) -> dict:
    """Read, resolve, write; return the summary dict (with a ``faults`` section if any).

    ``baselines``: also run the centralized baselines on the same links, for comparison
    (the summary's ``baselines``: :func:`pipeline.evaluation.report.baselines_beside`).

    ``outputs``: a :class:`pipeline.runfolder.OutputFiles` that puts ``out_csv`` in place
    with the command's other outputs (default: ``out_csv`` is written at once).

    ``resolution``: a rule of :mod:`pipeline.consistency.rules`, e.g. ``paper`` (Alg. 1) or
    ``evidence``; the evidence of a link here is its
    ``quality`` column read as ``1 − Lowe ratio`` (and the triangle support the robots
    compute), as a links file carries no keypoints or geometry.

    Raises
    ------
    InputError
        Bad input rows (see :func:`pipeline.inputs.linkscsv.read_links_csv`), a bad comm-graph file,
        ``out`` equal to the input, or a link between cameras that are not neighbours in the
        given comm graph (naming its row).
    """
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.budget import (
        BYTES_PER_CAMERA,
        BYTES_PER_EDGE,
        BYTES_PER_ROW,
        MemoryBudget,
        baselines_bytes,
        check_detection_memory,
        count_lines,
    )
    from pipeline.commgraph import links_off_graph, read_comm_graph
    from pipeline.consistency.rules import deleted_cases, rule_for_network
    from pipeline.consistency.setlists import bundle_budget
    from pipeline.faults import warn_rule_under_faults
    from pipeline.inputs.compact import compact_ids, fault_section_in_ids, faults_in_layout
    from pipeline.inputs.linkscsv import read_links_csv, write_links_csv
    from pipeline.outputs import require_input_file
    from pipeline.runfolder import output_path
    from pipeline.runs.transports import check_team_size, get_transport
    from pipeline.stages import ledger_from_consistency
    from pipeline.types import LinkLedger

    links_csv, out_csv = Path(links_csv), Path(out_csv)
    if out_csv.exists() and out_csv.resolve() == links_csv.resolve():
        raise InputError(f"--out {str(out_csv)!r} is the input file; the input is never "
                         "modified, choose a new file")
    # every allocation that grows with the input is counted before it is made
    budget = MemoryBudget(max_memory_gb)
    budget.add("the rows of the links file",
               count_lines(require_input_file(links_csv, "links file")) * BYTES_PER_ROW,
               "split the links file")
    if comm_graph_csv is not None:
        budget.add("the communication graph", count_lines(
            require_input_file(comm_graph_csv, "comm graph file")) * BYTES_PER_EDGE)
    lf = read_links_csv(links_csv)
    links = lf.links
    edges = None
    n_cams = None
    if comm_graph_csv is not None:
        edges = read_comm_graph(comm_graph_csv)
        n_cams = int(edges.max(initial=-1)) + 1
    # always the compact layout (pipeline.inputs.compact): memory follows the links, and the
    # merge rules (sync, evidence) order links of equal evidence by a hash of their global
    # feature ids, so one layout whatever the ids as given keeps the cuts the same however the
    # ids are spelled and on every transport (a process team runs on compact ids: no process
    # for an id without links)
    force = True
    ids = compact_ids(links, edges, n_cameras=n_cams, force=force)
    n = int(ids.cameras.max(initial=-1)) + 1
    robots = len(ids.features_per_camera)  # the cameras of the run (compact ids)
    budget.add(f"the robots of the {robots} cameras", robots * BYTES_PER_CAMERA,
               "fewer cameras (a comm graph naming only those with links)")
    # a run-output links.csv (e.g. our own output): its deleted rows stay deleted with their
    # reason and round; its kept rows are the links to make consistent
    active = lf.status == "kept" if lf.status is not None else np.ones(len(links), dtype=bool)
    if edges is not None and len(links):
        # a deleted row may join non-neighbours: clean-db cuts those links (not-comm-edge)
        off = links_off_graph(links, edges, n) & active
        if off.any():
            k = int(np.flatnonzero(off)[0])
            raise InputError(
                f"{links_csv}:{lf.line[k]}: link ({links.cam_i[k]},{links.feat_i[k]})-"
                f"({links.cam_j[k]},{links.feat_j[k]}) joins cameras {links.cam_i[k]} and "
                f"{links.cam_j[k]}, which are not neighbours in {comm_graph_csv}; add the edge "
                "or remove the link")
    all_links = links
    if not active.all():
        links = all_links.subset(active)
        ids = compact_ids(links, edges, n_cameras=n_cams, force=force)
    m, run_links, run_edges = ids.features_per_camera, ids.links, ids.edges
    if len(run_links):
        check_team_size(transport, len(m), "cameras in the links file" if edges is None
                        else "cameras in the links file and the comm graph")
    # the rule that will run: on a faulty network a rule that is not fault-tolerant gives way
    # to the fault-tolerant Alg. 1, whose detection is what must fit
    faulty = faults is not None and faults.any
    rule = rule_for_network(resolution, faulty)
    check_detection_memory(m, run_links, budget, detection=rule.detection,
                           set_lists=bundle_budget(len(m)) if rule.set_lists else None,
                           camera_sets=rule.camera_sets, in_flight=transport != "sim" or faulty)
    if baselines:
        budget.add("the centralized baselines (--baselines)",
                   baselines_bytes(m, run_links), "drop --baselines")
    if faults is not None:
        faults_in_layout(faults, ids)  # a crash of a robot not in the input is refused here
    # the input checked: a rule that gives way to Alg. 1 under the faults is warned of now, so
    # that a refused command prints its error line only
    warn_rule_under_faults(faults, resolution)
    before = count_conflicts(AssociationGraph(m, run_links)).as_dict()
    # without a link the robots have nothing to exchange: no team of processes is started
    # for it (a team over Zenoh needs two robots with something to say); the result is the
    # same empty association on every transport
    where = transport if len(run_links) else "sim"
    res, fault_section = get_transport(where).load().resolve(m, run_edges, run_links, faults,
                                                             resolution, ids)
    after = count_conflicts(AssociationGraph(m, res.kept())).as_dict()
    ledger = ledger_from_consistency(res)
    ledger.links = links  # the ids as given (the stage may have run on compact ones)
    if lf.status is not None:
        # rows the input file had already deleted stay deleted with their reason and round
        full = LinkLedger.all_kept(all_links)
        full.place(np.flatnonzero(active), ledger)
        old = np.flatnonzero(~active)
        full.status[old], full.reason[old], full.round[old] = "deleted", lf.reason[old], lf.round[old]
        ledger = full
    ledger.truth = lf.truth  # a run output's truth column goes through (file order)
    # the input's quality goes through, a last column (the rows in file order)
    write_links_csv(output_path(outputs, out_csv, "--out"), ledger, quality=lf.has_quality)
    st = res.stats
    summary = {
        # the cameras that appear (in a link or a comm edge), whatever the layout the robots
        # ran on (ids as given hold the ids between them too; a process team does not)
        "input": str(links_csv), "output": str(out_csv), "cameras": int(np.unique(np.concatenate(
            [all_links.cam_i, all_links.cam_j] + ([edges.ravel()] if edges is not None
                                                  else []))).size),
        "comm_edges": int(len(edges)) if edges is not None else
        int(np.unique(links.cam_i * n + links.cam_j).size),
        "links": len(all_links), "deleted": int(res.deleted.sum()),
        "previously_deleted": int((~active).sum()),
        "resolution_method": res.stats["resolution"],
        # the cases of the rule that ran (on a faulty network Alg. 1 may run instead)
        "deleted_by_case": {c: int((res.case == c).sum())
                            for c in deleted_cases(res.stats["resolution"])},
        "before": before, "after": after,
        "resolution": {k: st[k] for k in ("iterations", "detection_rounds", "resolution_rounds",
                                          "closing_rounds", "messages", "bytes",
                                          "max_robot_memory_bytes") if k in st},
    }
    from pipeline.evaluation.quality import quality_evidence

    # does the quality carry evidence? (the merge rules weigh it; a reversed one is warned of)
    summary["quality_evidence"] = quality_evidence(m, run_links)
    from pipeline.consistency.rules import get_rule

    # whether the rule that ran reads the quality at all (Alg. 1 does not): the warning says so
    summary["quality_evidence"]["read_by_rule"] = bool(
        get_rule(res.stats["resolution"]).needs_evidence)
    if baselines:
        from pipeline.evaluation.report import baselines_beside
        from pipeline.progress import StageTimer

        # centralized, and the spectral ones grow fast with the largest set (minutes on tens
        # of thousands of features in one set): said before they start, timed when done
        with StageTimer().stage("baselines", f"the centralized baselines beside the rule, "
                                             f"on {int(m.sum())} features and {len(run_links)} "
                                             "links (minutes on large sets)"):
            summary["baselines"] = baselines_beside(m, run_links, ~res.deleted)
    if fault_section is not None:
        summary["faults"] = fault_section_in_ids(fault_section, ids)
    if "team" in res.stats:
        summary["team"] = res.stats["team"]
    return summary
