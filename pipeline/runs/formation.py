"""The ``run-formation`` job: a rendered formation through every stage, evaluated against its
ground truth, written as a run folder.

:func:`run_formation` hands the robots' part (render, features, matching, consistency,
fusion) to a transport of :mod:`pipeline.runs.transports` (the simulator, or one process per
robot over Zenoh), then :func:`write_formation_run` evaluates the result against the ground
truth (:mod:`pipeline.evaluation`) and writes ``report.json`` (built by
:mod:`pipeline.evaluation.report`), ``links.csv``, ``sparse/`` and ``recording.rrd``
atomically. :mod:`pipeline.runs.images` does the same for photographs.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pipeline.association import AssociationGraph
from pipeline.consistency.rules import DEFAULT_RESOLUTION
from pipeline.faults import FaultConfig
from pipeline.outcome import NO_LINKS_WHY, flag_result, merge_radius_why
from pipeline.progress import StageTimer
from pipeline.runfolder import atomic_run_folder, write_json_atomic
from pipeline.stages import CleaningResult, consistency_stage, evidence_inputs, merge_radius_for
from pipeline.types import Links, RunRecord

__all__ = ["FormationConfig", "run_formation", "write_formation_run"]




@dataclass
class FormationConfig:
    """Options of ``run-formation`` (defaults = ``make run-formation``)."""

    formation: str = "d"
    seed: int = 0
    size: tuple[int, int] = (640, 480)
    features: str = "sift"
    max_features: int = 2000
    robots: int | None = None
    graph: str | None = None
    tol_px: float = 2.0
    fusion: bool = True
    out: str | None = None
    rerun: bool = True
    faults: FaultConfig | None = None
    resolution: str = DEFAULT_RESOLUTION
    merge_radius: float | None = None
    #: the memory guard's limit for the stages counted once their inputs are known (the
    #: fusion stage: :func:`pipeline.budget.check_fusion_memory`); None: not checked
    max_memory_gb: float | None = None

    def out_dir(self) -> Path:
        if self.out:
            return Path(self.out)
        name = f"formation-{self.formation}" if self.robots is None else \
            f"formation-n{self.robots}-{self.graph}"
        return Path("runs") / name


def run_formation(config: FormationConfig, timer: StageTimer | None = None,
                  transport: str = "sim", **transport_options) -> Path:
    """Render a formation, run every stage, write the run folder; return its path.

    Stages: render → features → matching → consistency → fusion → triangulation (before and
    after, pycolmap with known poses) → evaluation against ground truth → outputs.
    ``transport``: a name of :mod:`pipeline.runs.transports` (``sim``: the robots are objects
    of this process; ``zenoh``: separate processes over Zenoh); the same run folder is
    written. ``transport_options`` go to the transport's ``formation`` job (e.g. ``kill``,
    ``workdir``, ``keep_run``, ``round_timeout_s`` of zenoh).
    """
    from pipeline.runs.transports import get_transport

    timer = timer or StageTimer()
    robots = get_transport(transport).load().formation(config, timer, **transport_options)
    return write_formation_run(config, robots.formation, robots.features, robots.matches,
                               robots.cleaning, timer, extra=robots.extra)


def write_formation_run(config: FormationConfig, formation, feats: list, matches: list,
                        cleaning: CleaningResult, timer: StageTimer,
                        extra: dict | None = None) -> Path:
    """Evaluate a formation run against ground truth and write its run folder.

    ``extra`` adds sections to ``report.json`` (e.g. ``team`` for a run over Zenoh).
    Steps: :func:`_evaluate` (the ledger's truth and every ground-truth section),
    :func:`_triangulate` (pycolmap with known poses, before and after; the fused landmarks'
    errors), then the report and the outputs (:func:`_write`).
    """
    from data_synth import formation_name, formation_used
    from pipeline.evaluation import report as sections

    out = config.out_dir()
    views, comm_edges = formation.views, np.asarray(formation.comm_edges)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    ledger = cleaning.ledger
    # the rule the consistency stage ran: on a faulty network a rule that is not
    # fault-tolerant gives way to Alg. 1 (pipeline.consistency.rules.rule_for_network)
    ran = cleaning.resolution_stats.get("resolution") or config.resolution
    # a faulty network, or a robot lost without one (a robot process killed)
    faulty = (config.faults is not None and config.faults.any) \
        or bool((ledger.reason == "robot-lost").any())
    evaluated = _evaluate(config, formation, feats, matches, ledger, timer, ran, faulty)
    triangulation, tri_after, gt_points, fused_errors = _triangulate(
        views, feats, ledger, cleaning, evaluated.pop("resolved_links"), timer)
    report = {
        "title": formation_name(config.formation, config.robots, config.graph,
                                len(comm_edges)) + f" (seed {config.seed})",
        "n_cameras": len(views),
        "comm_edges": comm_edges.tolist(),
        "features_per_camera": m.tolist(),
        "before": evaluated["before"],
        "after": evaluated["after"],
        "resolution": sections.resolution_section(ledger, cleaning.resolution_stats),
        "fusion": sections.fusion_section(ledger, cleaning.fusion_stats),
        "triangulation": triangulation,
        "pairwise": evaluated["pairwise"],
        "baselines": evaluated["baselines"],
        "resolution_quality": evaluated["resolution_quality"],
        "matching": sections.matching_section(matches),
        "ground_truth": {"tolerance_px": config.tol_px},
        "versions": sections.versions(),
        # the memory limit is a guard on the run, not an option of its outputs
        "config": {**{k: v for k, v in asdict(config).items() if k != "max_memory_gb"},
                   "formation": formation_used(config.formation, config.graph),
                   # the radius the keypoints were merged at (merge_radius null: the rule's)
                   "merge_radius_used_px": merge_radius_for(config.resolution,
                                                            config.merge_radius),
                   "out": str(out)},
    }
    if cleaning.faults is not None:
        report["faults"] = cleaning.faults
    report.update(extra or {})
    if fused_errors is not None:
        report["fusion"].update(fused_errors)

    flag_result(report, [v.name for v in views],
                no_links_why=NO_LINKS_WHY + merge_radius_why(config.merge_radius, config.size))
    md = sections.report_markdown(report)
    _write(out, config, report, md, views, feats, ledger, tri_after, gt_points,
           cleaning.fused_points, timer)
    print(md)
    return out


def _evaluate(config: FormationConfig, formation, feats: list, matches: list, ledger,
              timer: StageTimer, method: str | None = None, faulty: bool = False) -> dict:
    """The ground-truth sections of the report (``before``, ``after``, ``pairwise``,
    ``baselines``, ``resolution_quality``); sets ``ledger.truth``. Also returns
    ``resolved_links``, what the consistency stage kept (fusion ran on exactly these).
    ``method``: the resolution rule the consistency stage ran (default
    ``config.resolution``), whose row of ``resolution_quality`` is what the run cut
    (``faulty``: on a faulty network, which the other rules' rows do not share)."""
    from pipeline.consistency import centralized
    from pipeline.evaluation import report as sections
    from pipeline.evaluation.links import MissingLinks, link_truth
    from pipeline.evaluation.metrics import PairwiseTruth, true_pairs_all

    views, comm_edges = formation.views, np.asarray(formation.comm_edges)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    links = ledger.links
    kept = ledger.kept
    kept_links = links.subset(kept)
    with timer.stage("evaluate", f"ground truth at {config.tol_px} px"):
        truth = link_truth(formation, feats, links, tol_px=config.tol_px)
        truth = np.asarray(truth, dtype=bool)
        ledger.truth = truth.astype(np.int8)

        missing = MissingLinks(formation, feats, comm_edges, tol_px=config.tol_px)
        gt_pairs = PairwiseTruth(true_pairs_all(formation, feats, tol_px=config.tol_px),
                                 int(m.sum()))
        # several sections count and score the same kept subsets: each subset's association
        # graph (and its components) and pairwise scores are computed once
        graphs: dict = {}
        scored: dict = {}

        def graph_of(kept_subset: Links) -> AssociationGraph:
            key = _links_key(kept_subset)
            if key not in graphs:
                graphs[key] = AssociationGraph(m, kept_subset)
            return graphs[key]

        def pairwise_of(kept_subset: Links) -> dict:
            key = _links_key(kept_subset)
            if key not in scored:
                scored[key] = gt_pairs.scores(m, kept_subset, graph_of(kept_subset))
            return dict(scored[key])

        before = sections.association_counts(m, links, truth, missing(links), graph_of(links))
        after = sections.association_counts(m, kept_links, truth[kept], missing(kept_links),
                                            graph_of(kept_links))
        # what the consistency stage kept (fusion ran on exactly these links)
        resolved = kept | (ledger.reason == "fusion-outlier")
        resolved_links = links.subset(resolved)
        pairwise = {"before": pairwise_of(links), "after_resolution": pairwise_of(resolved_links),
                    "after": pairwise_of(kept_links)}
        baseline_masks = centralized.baselines(m, links, graph=graph_of(links))
        baselines = sections.baselines_section(m, links, truth, missing, pairwise_of,
                                               masks=baseline_masks, graph_of=graph_of)
        quality = sections.resolution_quality_section(
            m, links, truth, pairwise_of,
            _resolution_masks(views, feats, matches, comm_edges, links, truth,
                              method or config.resolution, resolved, baseline_masks,
                              graph_of(links), faulty=faulty),
            graph=graph_of(links))
    return {"before": before, "after": after, "pairwise": pairwise, "baselines": baselines,
            "resolution_quality": quality, "resolved_links": resolved_links}


def _triangulate(views, feats: list, ledger, cleaning: CleaningResult, resolved_links: Links,
                 timer: StageTimer):
    """pycolmap with known poses on all links and on the kept ones; the fused landmarks
    against pycolmap and the truth. Returns ``(triangulation section, the kept links'
    triangulation, ground-truth points per camera, fused-point errors or None)``."""
    # pycolmap is loaded only now: the earlier stages' peak memory does not include it
    from data_synth.ground_truth import points_from_keypoints
    from pipeline.evaluation import report as sections
    from pipeline.evaluation.triangulation import triangulate_tracks

    links = ledger.links
    kept_links = links.subset(ledger.kept)
    with timer.stage("triangulation", "pycolmap, known poses, before and after"):
        gt_points = [points_from_keypoints(v, f.keypoints)[0] if len(f) else np.zeros((0, 3))
                     for v, f in zip(views, feats, strict=True)]
        solved_tracks = {}  # the link sets below share most of their tracks
        tri_before = triangulate_tracks(views, feats, links, gt_points=gt_points,
                                        solved_tracks=solved_tracks)
        tri_after = triangulate_tracks(views, feats, kept_links, gt_points=gt_points,
                                       solved_tracks=solved_tracks)
        triangulation = {"before": tri_before.summary(), "after": tri_after.summary()}
        timer.note(f"after: {triangulation['after']['triangulated_tracks']} of "
                   f"{triangulation['after']['tracks']} tracks triangulated")
        fused_errors = None
        if cleaning.fused_points is not None:  # fused landmarks against pycolmap and the truth
            fused_errors = sections.fused_point_errors(
                views, feats, resolved_links, cleaning.fused_points, cleaning.fused_track_ids,
                gt_points, solved_tracks=solved_tracks,
                fused_track_features=cleaning.fused_track_features)
    return triangulation, tri_after, gt_points, fused_errors


def _write(out: Path, config: FormationConfig, report: dict, md: str, views, feats: list,
           ledger, tri_after, gt_points: list, fused_points, timer: StageTimer) -> None:
    """The run folder, atomically: ``links.csv``, ``sparse/``, ``recording.rrd`` (with
    ``config.rerun``) and ``report.json`` (with the stage timings)."""
    from pipeline.evaluation import report as sections
    from pipeline.evaluation.triangulation import write_reconstruction
    from pipeline.inputs.linkscsv import write_links_csv

    with timer.stage("write", str(out)):
        with atomic_run_folder(out) as tmp:
            write_links_csv(tmp / "links.csv", ledger)
            write_reconstruction(tmp / "sparse", views, feats, tri_after)
            if config.rerun:
                from viz.rerun_log import log_run

                all_gt = np.concatenate(gt_points) if gt_points else np.zeros((0, 3))
                record = RunRecord(
                    views=views, features=feats, ledger=ledger,
                    points=tri_after.xyz[tri_after.ok],
                    point_tracks=np.flatnonzero(tri_after.ok),
                    gt_points=sections.track_gt_points(all_gt, tri_after),
                    fused_points=fused_points,
                    report_markdown=md)
                log_run(tmp / "recording.rrd", record)
            report["timings_s"] = {k: round(v, 4) for k, v in timer.timings.items()}
            write_json_atomic(tmp / "report.json", report)


def _links_key(links: Links) -> bytes:
    """The contents of ``links`` as one hashable value (equal iff the links are equal)."""
    return b"".join(np.ascontiguousarray(a, dtype=np.int64).tobytes() + b"|" for a in
                    (links.cam_i, links.feat_i, links.cam_j, links.feat_j))


def _resolution_masks(views, feats, matches, comm_edges, links: Links, truth: np.ndarray,
                      method: str, resolved: np.ndarray, baseline_masks: dict | None = None,
                      graph: AssociationGraph | None = None, faulty: bool = False) -> dict:
    """Kept masks ``(L,)`` of every resolution on the same input, for the report only.

    The run's own method (``resolved``: what its consistency stage kept), every other
    resolution rule (:mod:`pipeline.consistency.rules`, run here on the fault-free network), every centralized baseline
    (``baseline_masks``: ``centralized.baselines(m, links)`` when the caller has it) and
    the oracle (:func:`pipeline.evaluation.oracle.oracle_cut`, which knows the truth); ``graph``: the
    :class:`AssociationGraph` of ``links``, when the caller has it. ``faulty``: the run's
    stage ran on a faulty network (its links cut ``robot-lost`` are in ``resolved``), so a
    rule that cuts as ``method`` by construction is run fault-free instead of sharing its row.
    """
    from pipeline.consistency import centralized
    from pipeline.consistency.rules import get_rule, rule_names
    from pipeline.evaluation.oracle import oracle_cut

    m = np.array([len(f) for f in feats], dtype=np.int64)
    masks = {method: np.asarray(resolved, dtype=bool)}
    for other in rule_names():
        same = get_rule(other).cuts_as
        if other not in masks and same in masks and not (faulty and same == method):
            masks[other] = masks[same]  # the same cuts by construction (rules.py, cuts_as)
        elif other not in masks:
            evidence = evidence_inputs(views, feats, links, matches) \
                if get_rule(other).needs_evidence else None
            res, _ = consistency_stage(m, comm_edges, links, resolution=other, evidence=evidence)
            masks[other] = ~res.deleted
    ordered = {k: masks[k] for k in rule_names()}
    if baseline_masks is None:
        baseline_masks = centralized.baselines(m, links, graph=graph)
    ordered.update({k: np.asarray(v, dtype=bool) for k, v in baseline_masks.items()})
    ordered["oracle"] = oracle_cut(m, links, truth, graph=graph)
    return ordered
