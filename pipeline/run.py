"""Run the whole pipeline and write a run folder (DESIGN.md "Data flow" and "Run outputs").

``clean_association`` is the product's core on any input (rendered or real):
consistency (detection + resolution by message passing) then robust distributed fusion.
``run_formation`` wraps it for a rendered formation with ground truth and writes
``report.json``, ``links.csv``, ``sparse/`` and ``recording.rrd`` atomically.
"""

from __future__ import annotations

import platform
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from pipeline.association import AssociationGraph, count_conflicts
from pipeline.faults import FaultConfig
from pipeline.progress import StageTimer
from pipeline.runfolder import atomic_run_folder, write_json_atomic
from pipeline.types import Links, RunRecord, View

__all__ = ["FormationConfig", "Cleaning", "extract_and_match", "clean_association",
           "association_counts", "resolution_section", "run_formation", "versions"]


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

    def out_dir(self) -> Path:
        if self.out:
            return Path(self.out)
        name = f"formation-{self.formation}" if self.robots is None else \
            f"formation-n{self.robots}-{self.graph}"
        return Path("runs") / name


@dataclass
class Cleaning:
    """What the consistency and fusion stages decided for every link (``(L,)`` arrays)."""

    links: Links
    status: np.ndarray
    reason: np.ndarray
    round: np.ndarray
    iteration: np.ndarray
    case: np.ndarray
    conflictive_before: np.ndarray
    resolution_stats: dict
    fusion_stats: dict = field(default_factory=dict)
    fused_points: np.ndarray | None = None
    fused_track_ids: np.ndarray | None = None
    faults: dict | None = None

    @property
    def kept(self) -> np.ndarray:
        return self.status == "kept"


def versions() -> dict:
    """Versions of Python and the libraries whose behaviour the figures depend on."""
    import cv2
    import pycolmap
    import rerun
    import scipy

    from pipeline import __version__
    return {"formation-match": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "opencv": cv2.__version__,
            "pycolmap": pycolmap.__version__, "rerun-sdk": rerun.__version__}


def _conflictive_links(features_per_camera, links: Links) -> np.ndarray:
    from pipeline.association import conflictive_labels

    graph = AssociationGraph(features_per_camera, links)
    labels, _, conflictive = conflictive_labels(graph)
    a, _ = graph.global_ids()
    return conflictive[labels[a]] if len(links) else np.zeros(0, dtype=bool)


def extract_and_match(views: list[View], comm_edges: np.ndarray, method: str,
                      max_features: int, timer: StageTimer) -> tuple[list, list, Links]:
    """Features of every camera, then matching on the communication edges only.

    Returns ``(features, matches, links)``: per-camera Features, per-edge PairMatches and all
    links (``Links.from_matches``).
    """
    from pipeline.features import extract_all
    from pipeline.matching import match_edges

    with timer.stage("features", f"{method}, at most {max_features} per image"):
        feats = extract_all(views, method, max_features)
        timer.note(f"features per camera: {[len(f) for f in feats]}")
    with timer.stage("matching", f"{len(comm_edges)} communication edges"):
        matches = match_edges(feats, views, comm_edges)
        links = Links.from_matches(matches)
        timer.note(f"{len(links)} links")
    return feats, matches, links


def clean_association(views: list[View], features: list, comm_edges: np.ndarray, links: Links,
                      *, fusion: bool = True, timer: StageTimer | None = None,
                      faults: FaultConfig | None = None) -> Cleaning:
    """Consistency (Aragüés et al., Sec. III–IV) then fusion (Montijano et al.) on ``links``.

    Fusion needs camera poses; it is skipped (and says so in ``fusion_stats``) without them.
    With ``faults`` on, the consistency stage runs on the faulty network (and once more
    fault-free, for the ``faults`` section's extra rounds and messages); a switching topology
    is used by the fusion consensus too.
    """
    from pipeline.consistency import resolve_conflicts

    timer = timer or StageTimer(verbose=False)
    m = np.array([len(f) for f in features], dtype=np.int64)
    L = len(links)
    with timer.stage("consistency", "distributed detection + resolution"):
        conflictive_before = _conflictive_links(m, links)
        faulty = faults is not None and faults.any
        opts = faults.network_options(comm_edges, len(m)) if faulty else None
        res = resolve_conflicts(m, comm_edges, links, opts)
        status = np.where(res.deleted, "deleted", "kept").astype(object)
        reason = np.asarray(res.reason, dtype=object).copy()
        rnd = np.asarray(res.round, dtype=np.int64).copy()
        iteration = np.asarray(res.iteration, dtype=np.int64).copy()
        case = np.asarray(res.case, dtype=object).copy()
        timer.note(f"{int(res.deleted.sum())} of {L} links cut in "
                   f"{res.stats.get('iterations')} iteration(s)")
    cleaning = Cleaning(links, status, reason, rnd, iteration, case, conflictive_before,
                        dict(res.stats))
    if faulty:
        from pipeline.faults import fault_report

        cleaning.faults = fault_report(faults, res, resolve_conflicts(m, comm_edges, links))
    has_poses = all(v.R is not None and v.t is not None for v in views)
    if not fusion:
        cleaning.fusion_stats = {"enabled": False, "reason": "disabled by option"}
    elif not has_poses:
        cleaning.fusion_stats = {"enabled": False, "reason": "camera poses unknown"}
    else:
        from pipeline.fusion.landmarks import fuse_tracks

        with timer.stage("fusion", "robust distributed fusion by dynamic voting"):
            kept_idx = np.flatnonzero(cleaning.kept)
            fr = fuse_tracks(views, features, links.subset(kept_idx), comm_edges,
                             topology=faults.topology(comm_edges) if faulty else None)
            cut = kept_idx[np.asarray(fr.cut_links, dtype=bool)]
            cleaning.status[cut] = "deleted"
            cleaning.reason[cut] = "fusion-outlier"
            cleaning.round[cut] = int(fr.stats.get("rounds", -1))
            cleaning.fusion_stats = {"enabled": True, **dict(fr.stats),
                                     "observations_cut_links": int(len(cut))}
            cleaning.fused_points = np.asarray(fr.points)
            cleaning.fused_track_ids = np.asarray(fr.track_ids)
            timer.note(f"{len(cut)} links cut as fusion outliers")
    return cleaning


def association_counts(m, links: Links, truth: np.ndarray | None, missing: int | None) -> dict:
    counts = count_conflicts(AssociationGraph(m, links)).as_dict()
    if truth is not None:
        counts["good_links"] = int(truth.sum())
        counts["spurious_links"] = int((~truth).sum())
        counts["missing_links"] = int(missing) if missing is not None else None
        counts["precision"] = float(truth.mean()) if len(truth) else None
    return counts


def resolution_section(cleaning: Cleaning, truth: np.ndarray | None) -> dict:
    cut = cleaning.reason == "resolution"
    stats = cleaning.resolution_stats
    out = {
        "iterations": stats.get("iterations"),
        "deleted_links": int(cut.sum()),
        "detection_rounds": stats.get("detection_rounds"),
        "resolution_rounds": stats.get("resolution_rounds"),
        "messages": stats.get("messages"),
        "bytes": stats.get("bytes"),
        "max_robot_memory_bytes": stats.get("max_robot_memory_bytes"),
    }
    # Alg. 1 line 9: case (b) feature already in another component, (c) its camera already in
    out["deleted_by_case"] = {c: int((cut & (cleaning.case == c)).sum()) for c in ("b", "c")}
    if truth is not None:
        out["good_deleted"] = int((cut & truth).sum())
        out["spurious_deleted"] = int((cut & ~truth).sum())
    out["details"] = {k: v for k, v in stats.items() if k not in out}
    return out


def report_markdown(report: dict) -> str:
    """The paper-style table (Tables III/IV rows) of one run as markdown."""
    b, a, r = report["before"], report["after"], report["resolution"]
    rows = [("Association sets", "association_sets"), ("Conflictive sets (c)", "conflictive_sets"),
            ("Number of features m_sum", "m_sum"), ("Conflictive features", "conflictive_features"),
            ("Links", "links"), ("Good links", "good_links"), ("Spurious links", "spurious_links"),
            ("Missing links", "missing_links")]
    lines = [f"## {report.get('title', 'run')}", "", "| | before | after |", "|---|---:|---:|"]
    for label, key in rows:
        if key in b:
            lines.append(f"| {label} | {b[key]} | {a[key]} |")
    lines += ["", "| Resolution | |", "|---|---:|"]
    for key in ("iterations", "deleted_links", "good_deleted", "spurious_deleted",
                "detection_rounds", "resolution_rounds", "messages", "bytes"):
        if key in r:
            lines.append(f"| {key.replace('_', ' ')} | {r[key]} |")
    fusion, faults = report.get("fusion") or {}, report.get("faults") or {}
    if "cut_links" in fusion:
        lines.append(f"| links cut by fusion (fusion-outlier) | {fusion['cut_links']} |")
    if "links_cut_robot_lost" in faults:
        lines.append(f"| links cut to lost robots (robot-lost) | {faults['links_cut_robot_lost']} |")
    return "\n".join(lines) + "\n"


def run_formation(config: FormationConfig, timer: StageTimer | None = None) -> Path:
    """Render a formation, run every stage, write the run folder; return its path.

    Stages: render → features → matching → consistency → fusion → triangulation (before and
    after, pycolmap with known poses) → evaluation against ground truth → outputs.
    """
    import data_synth
    from data_synth.ground_truth import points_from_keypoints
    from pipeline.consistency import centralized
    from pipeline.evaluate import link_truth, missing_links
    from pipeline.linkscsv import write_links_csv
    from pipeline.metrics import association_pairs, pairwise_scores, true_pairs_all
    from pipeline.triangulation import triangulate_tracks, write_reconstruction

    timer = timer or StageTimer()
    out = config.out_dir()
    with timer.stage("render", f"formation {config.formation}, seed {config.seed}, "
                     f"{config.size[0]}x{config.size[1]}"):
        formation = data_synth.render(config.formation, seed=config.seed, size=config.size,
                                      n_robots=config.robots, graph=config.graph)
        views, comm_edges = formation.views, np.asarray(formation.comm_edges)
    feats, matches, links = extract_and_match(views, comm_edges, config.features,
                                              config.max_features, timer)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    cleaning = clean_association(views, feats, comm_edges, links, fusion=config.fusion,
                                 faults=config.faults,
                                 timer=timer)
    kept = cleaning.kept
    kept_links = links.subset(kept)

    with timer.stage("evaluate", f"ground truth at {config.tol_px} px"):
        truth = link_truth(formation, feats, links, tol_px=config.tol_px)
        truth = np.asarray(truth, dtype=bool)
        before = association_counts(m, links, truth,
                                     missing_links(formation, feats, links, comm_edges,
                                                   tol_px=config.tol_px))
        after = association_counts(m, kept_links, truth[kept],
                                    missing_links(formation, feats, kept_links, comm_edges,
                                                  tol_px=config.tol_px))
        gt_pairs = true_pairs_all(formation, feats, tol_px=config.tol_px)
        m_total = int(m.sum())
        # what the consistency stage kept (fusion ran on exactly these links)
        resolved = cleaning.kept | (cleaning.reason == "fusion-outlier")
        resolved_links = links.subset(resolved)
        pairwise = {"before": pairwise_scores(association_pairs(m, links), gt_pairs, m_total),
                    "after_resolution": pairwise_scores(association_pairs(m, resolved_links),
                                                        gt_pairs, m_total),
                    "after": pairwise_scores(association_pairs(m, kept_links), gt_pairs, m_total)}
        baselines = {}
        for name, keep_mask in centralized.baselines(m, links).items():
            keep_mask = np.asarray(keep_mask, dtype=bool)
            bl = links.subset(keep_mask)
            baselines[name] = {
                **association_counts(m, bl, truth[keep_mask],
                                      missing_links(formation, feats, bl, comm_edges,
                                                    tol_px=config.tol_px)),
                "deleted_links": int((~keep_mask).sum()),
                "good_deleted": int((~keep_mask & truth).sum()),
                "spurious_deleted": int((~keep_mask & ~truth).sum()),
                "pairwise": pairwise_scores(association_pairs(m, bl), gt_pairs, m_total),
            }
    with timer.stage("triangulation", "pycolmap, known poses, before and after"):
        gt_points = [points_from_keypoints(v, f.keypoints)[0] if len(f) else np.zeros((0, 3))
                     for v, f in zip(views, feats, strict=True)]
        tri_before = triangulate_tracks(views, feats, links, gt_points=gt_points)
        tri_after = triangulate_tracks(views, feats, kept_links, gt_points=gt_points)
        triangulation = {"before": tri_before.summary(), "after": tri_after.summary()}
        timer.note(f"after: {triangulation['after']['triangulated_tracks']} of "
                   f"{triangulation['after']['tracks']} tracks triangulated")

    report = {
        "title": f"formation {config.formation} (seed {config.seed})",
        "n_cameras": len(views),
        "comm_edges": comm_edges.tolist(),
        "features_per_camera": m.tolist(),
        "before": before,
        "after": after,
        "resolution": resolution_section(cleaning, truth),
        "fusion": _fusion_section(cleaning, truth),
        "triangulation": triangulation,
        "pairwise": pairwise,
        "baselines": baselines,
        "matching": {"edges": [{"i": p.i, "j": p.j, "links": int(len(p.pairs)),
                                "putative": int(p.n_putative), "reason": p.reason}
                               for p in matches]},
        "ground_truth": {"tolerance_px": config.tol_px},
        "versions": versions(),
        "config": {**asdict(config), "out": str(out)},
    }
    if cleaning.faults is not None:
        report["faults"] = cleaning.faults
    if cleaning.fused_points is not None:
        report["fusion"].update(_fused_point_errors(views, feats, resolved_links, cleaning,
                                                    gt_points))

    md = report_markdown(report)
    with timer.stage("write", str(out)):
        with atomic_run_folder(out) as tmp:
            write_links_csv(tmp / "links.csv", links, cleaning.status, cleaning.reason,
                            cleaning.round, truth.astype(np.int8))
            write_reconstruction(tmp / "sparse", views, feats, tri_after)
            if config.rerun:
                from viz.rerun_log import log_run

                all_gt = np.concatenate(gt_points) if gt_points else np.zeros((0, 3))
                record = RunRecord(
                    views=views, features=feats, links=links,
                    status=cleaning.status.astype(str), reason=cleaning.reason.astype(str),
                    round=cleaning.round, iteration=cleaning.iteration,
                    conflictive_before=cleaning.conflictive_before,
                    truth=truth.astype(np.int8),
                    points=tri_after.xyz[tri_after.ok],
                    point_tracks=np.flatnonzero(tri_after.ok),
                    gt_points=_track_gt_points(all_gt, tri_after),
                    fused_points=cleaning.fused_points,
                    report_markdown=md)
                log_run(tmp / "recording.rrd", record)
            report["timings_s"] = {k: round(v, 4) for k, v in timer.timings.items()}
            write_json_atomic(tmp / "report.json", report)
    print(md)
    return out


def _fusion_section(cleaning: Cleaning, truth: np.ndarray) -> dict:
    cut = cleaning.reason == "fusion-outlier"
    out = dict(cleaning.fusion_stats)
    out["cut_links"] = int(cut.sum())
    out["cut_spurious"] = int((cut & ~truth).sum())
    out["cut_good"] = int((cut & truth).sum())
    return out


def _track_gt_points(all_gt: np.ndarray, tri) -> np.ndarray:
    """Ground-truth point of each triangulated track (medoid of its observations' points)."""
    from pipeline.triangulation import medoid

    pts = [medoid(all_gt[t]) for t, ok in zip(tri.track_features, tri.ok, strict=True) if ok]
    pts = np.array(pts).reshape(-1, 3)
    return pts[np.isfinite(pts).all(axis=1)]


def _fused_point_errors(views, feats, resolved_links: Links, cleaning: Cleaning,
                        gt_points: list) -> dict:
    """Fused landmarks against ground truth and against pycolmap on the same tracks.

    Fusion runs on the links kept by resolution; its tracks are numbered like
    :func:`pipeline.association.association_sets` on those links (smallest feature id), so
    the pycolmap triangulation of the same links gives the point to compare with.
    """
    from pipeline.association import association_sets
    from pipeline.triangulation import medoid, triangulate_tracks

    m = np.array([len(f) for f in feats], dtype=np.int64)
    _, tracks = association_sets(m, resolved_links)
    tri = triangulate_tracks(views, feats, resolved_links)
    all_gt = np.concatenate(gt_points) if gt_points else np.zeros((0, 3))
    ids = np.asarray(cleaning.fused_track_ids, dtype=np.int64)
    pts = np.asarray(cleaning.fused_points, dtype=np.float64).reshape(-1, 3)
    gt = np.array([medoid(all_gt[tracks[k]]) for k in ids]).reshape(-1, 3)
    err_gt = np.linalg.norm(pts - gt, axis=1)
    err_gt = err_gt[np.isfinite(err_gt)]
    ok = tri.ok[ids]
    err_colmap = np.linalg.norm(pts[ok] - tri.xyz[ids[ok]], axis=1)
    err_colmap_gt = np.linalg.norm(tri.xyz[ids[ok]] - gt[ok], axis=1)
    err_colmap_gt = err_colmap_gt[np.isfinite(err_colmap_gt)]

    def med(a):
        return float(np.median(a)) if len(a) else None

    return {"fused_points": int(len(pts)),
            "median_error_vs_ground_truth": med(err_gt),
            "p90_error_vs_ground_truth": float(np.percentile(err_gt, 90)) if len(err_gt) else None,
            "median_pycolmap_error_vs_ground_truth": med(err_colmap_gt),
            "median_distance_to_pycolmap": med(err_colmap)}
