"""The sections of ``report.json`` and its markdown tables (docs/DESIGN.md "Run outputs").

Every run path (rendered formations, real photographs) builds its report from these pieces,
so one figure is computed in one place: counts of the association graph (Aragüés et al.,
Tables III–IV rows), the resolution and fusion sections read from the
:class:`~pipeline.types.LinkLedger`, the centralized baselines, the matching section, and
the paper's own Tables III–IV for side-by-side printing.
"""

from __future__ import annotations

import platform

import numpy as np

from pipeline.association import AssociationGraph, count_conflicts
from pipeline.consistency.rules import deleted_cases
from pipeline.evaluation.metrics import NOT_DEFINED
from pipeline.types import LinkLedger, Links

__all__ = ["PAPER_TABLE_III_IV", "versions", "association_counts", "resolution_section",
           "sets_solved",
           "fusion_section", "baselines_section", "baselines_beside", "baselines_lines", "resolution_quality_section",
           "matching_section", "report_markdown",
           "mapping_markdown", "mapping_summaries_markdown", "images_report_markdown",
           "track_gt_points", "fused_point_errors"]

#: Aragüés et al., Tables III and IV (SURF, real images, no ground truth), formations (a)–(d),
#: keyed by what each row counts. Table IV's fifth and sixth rows are read by the text beside
#: them, "The spurious and the good links that the algorithm deletes [...] are shown in fifth
#: and sixth rows of table IV respectively": its row "Good deleted links (true positives)"
#: counts the *spurious* links deleted (a right deletion), "Spurious deleted links (false
#: positives)" the *good* links deleted. "Well solved": a conflictive set none of whose links
#: the algorithm keeps is spurious (the text: "a conflict as well solved when it does not
#: contain any spurious edge in any of the associations that the algorithm returns").
PAPER_TABLE_III_IV = {
    "Association sets": (528, 590, 605, 632),
    "Conflictive sets (c)": (2, 22, 31, 72),
    "Number of features m_sum": (1335, 1643, 1743, 2069),
    "Conflictive features": (14, 144, 204, 521),
    "Inconsistencies well solved": (1, 20, 24, 55),
    "Inconsistencies wrongly solved": (1, 2, 7, 17),
    "Deleted links": (2, 26, 46, 131),
    "Good deleted links": (1, 24, 27, 88),
    "Spurious deleted links": (1, 2, 19, 43),
}


def versions() -> dict:
    """Versions of Python and the libraries whose behaviour the figures depend on.

    Rerun's is read from the installed package metadata, so that a run without a recording
    (``--no-rerun``) does not import Rerun only to name its version.
    """
    from importlib.metadata import PackageNotFoundError, version

    import cv2
    import scipy

    from pipeline import __version__, colmap

    try:
        rerun_version = version("rerun-sdk")
    except PackageNotFoundError:
        rerun_version = None
    return {"formation-match": __version__, "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "opencv": cv2.__version__,
            "pycolmap": colmap.version(), "rerun-sdk": rerun_version}


def association_counts(m, links: Links, good: np.ndarray | None, missing: int | None,
                       graph: AssociationGraph | None = None) -> dict:
    """Counts of the association graph of ``links`` (Tables III–IV rows) and, with ``good``
    (``(L,)`` bool ground truth of ``links``), the good / spurious / missing links.
    ``graph``: the :class:`AssociationGraph` of ``links``, when the caller has it."""
    counts = count_conflicts(AssociationGraph(m, links) if graph is None else graph).as_dict()
    if good is not None:
        counts["good_links"] = int(good.sum())
        counts["spurious_links"] = int((~good).sum())
        counts["missing_links"] = int(missing) if missing is not None else None
        counts["precision"] = float(good.mean()) if len(good) else None
    return counts


def resolution_section(ledger: LinkLedger, stats: dict) -> dict:
    """The report's ``resolution`` section: links cut by the resolution (``method``: the rule
    of :mod:`pipeline.consistency.rules` that ran, e.g. Alg. 1 ``paper`` or ``evidence``) and
    the stage's costs."""
    cut = ledger.reason == "resolution"
    out = {
        "method": stats.get("resolution", "paper"),
        "iterations": stats.get("iterations"),
        "deleted_links": int(cut.sum()),
        "detection_rounds": stats.get("detection_rounds"),
        "resolution_rounds": stats.get("resolution_rounds"),
        "messages": stats.get("messages"),
        "bytes": stats.get("bytes"),
        "max_robot_memory_bytes": stats.get("max_robot_memory_bytes"),
    }
    # Alg. 1 line 9: case (b) feature already in another component, (c) its camera already in;
    # then the cases of the rule that ran (pipeline.consistency.rules)
    out["deleted_by_case"] = {c: int((cut & (ledger.case == c)).sum())
                              for c in deleted_cases(out["method"])}
    good = ledger.good
    if good is not None:
        out["good_deleted"] = int((cut & good).sum())
        out["spurious_deleted"] = int((cut & ~good).sum())
        out["sets_well_solved"], out["sets_wrongly_solved"] = sets_solved(ledger, good)
    out["details"] = {k: v for k, v in stats.items() if k not in out and k != "resolution"}
    return out


def sets_solved(ledger: LinkLedger, good: np.ndarray) -> tuple[int, int]:
    """Conflictive sets of the input (Def. 2.4) that the consistency stage solved well and
    wrongly (Table IV, :data:`PAPER_TABLE_III_IV`): wrongly when one of the set's links it kept
    (not cut ``resolution`` or ``robot-lost``; fusion comes after) is spurious."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    inside = np.flatnonzero(ledger.conflictive_before)
    if not inside.size:
        return 0, 0
    L = ledger.links
    width = int(max(L.feat_i[inside].max(), L.feat_j[inside].max())) + 1
    a = L.cam_i[inside].astype(np.int64) * width + L.feat_i[inside]
    b = L.cam_j[inside].astype(np.int64) * width + L.feat_j[inside]
    ids, ends = np.unique(np.r_[a, b], return_inverse=True)
    ends = ends.reshape(2, -1)
    _, comp = connected_components(coo_matrix((np.ones(inside.size), (ends[0], ends[1])),
                                              shape=(ids.size, ids.size)), directed=False)
    sets = comp[ends[0]]  # the conflictive set of each link inside one
    kept = ~np.isin(ledger.reason[inside], ("resolution", "robot-lost"))
    wrong = np.unique(sets[kept & ~good[inside]]).size
    n_sets = int(comp.max()) + 1
    return n_sets - wrong, wrong


def fusion_section(ledger: LinkLedger, stats: dict) -> dict:
    """The report's ``fusion`` section: the stage's own figures and the links it cut (good and
    spurious among them when the truth is known)."""
    cut = ledger.reason == "fusion-outlier"
    out = {**dict(stats), "cut_links": int(cut.sum())}
    good = ledger.good
    if good is not None:
        out["cut_spurious"] = int((cut & ~good).sum())
        out["cut_good"] = int((cut & good).sum())
    return out


def baselines_section(m, links: Links, good: np.ndarray | None = None, missing=None,
                      pairwise=None, masks: dict | None = None, graph_of=None) -> dict:
    """The centralized baselines (:func:`pipeline.consistency.centralized.baselines`) on the
    same links, for comparison only (never used by the robots).

    Parameters
    ----------
    m : (n,) int — features per camera
    links : Links, (L,)
    good : (L,) bool or None — ground truth of ``links``
    missing : callable ``Links -> int`` or None — missing links of a kept subset
    pairwise : callable ``Links -> dict`` or None — pairwise scores of a kept subset
    masks : dict or None — ``centralized.baselines(m, links)`` when the caller has it
    graph_of : callable ``Links -> AssociationGraph`` or None — the graph of a kept subset,
        when the caller keeps them
    """
    from pipeline.consistency import centralized

    out = {}
    for name, keep_mask in (centralized.baselines(m, links) if masks is None else masks).items():
        keep_mask = np.asarray(keep_mask, dtype=bool)
        kept = links.subset(keep_mask)
        row = {**association_counts(m, kept, None if good is None else good[keep_mask],
                                    None if missing is None else missing(kept),
                                    None if graph_of is None else graph_of(kept)),
               "deleted_links": int((~keep_mask).sum())}
        if good is not None:
            row["good_deleted"] = int((~keep_mask & good).sum())
            row["spurious_deleted"] = int((~keep_mask & ~good).sum())
        if pairwise is not None:
            row["pairwise"] = pairwise(kept)
        out[name] = row
    return out


def baselines_beside(m, links: Links, kept: np.ndarray) -> dict:
    """The centralized baselines on the links a job resolved, beside the rule's decisions,
    for a job without ground truth (``resolve --baselines``, ``clean-db --baselines``).

    Per baseline (:data:`pipeline.consistency.centralized.BASELINES`): the counts of its
    association (conflictive sets and features), ``deleted_links``, ``decided_otherwise``
    (links it keeps where the rule cut them, or cuts where the rule kept them) and its CPU
    time; for comparison only, never used by the robots.

    Parameters
    ----------
    m : (n,) int — features per camera
    links : Links, (L,) — the links the rule ran on
    kept : (L,) bool — the rule's decisions
    """
    import time

    from pipeline.consistency import centralized

    kept = np.asarray(kept, dtype=bool)
    uf = centralized.union_find_conflicts(m, links)  # the same sets for all
    masks, cpu = {}, {}
    for name, fn in centralized.BASELINES.items():
        t0 = time.process_time()
        masks[name] = np.asarray(fn(m, links, _uf=uf), dtype=bool)
        cpu[name] = round(time.process_time() - t0, 3)
    out = baselines_section(m, links, masks=masks)
    for name, row in out.items():
        row.update(decided_otherwise=int((masks[name] != kept).sum()), cpu_s=cpu[name])
    return out


def baselines_lines(section: dict, rule: str) -> list[str]:
    """One printed line per baseline of :func:`baselines_beside`'s ``section``."""
    return [f"baseline {name}: {bl['deleted_links']} links deleted, {bl['conflictive_sets']} "
            f"conflictive sets left, {bl['decided_otherwise']} links decided otherwise than "
            f"{rule} ({bl['cpu_s']:.2f} s CPU)" for name, bl in section.items()]


def resolution_quality_section(m, links: Links, good: np.ndarray, pairwise,
                               kept_masks: dict, graph: AssociationGraph | None = None) -> dict:
    """Which links each resolution cut on the same input, against the truth.

    Parameters
    ----------
    m : (n,) int — features per camera
    links : Links, (L,) — the input of the resolution
    good : (L,) bool — ground truth of ``links``
    pairwise : callable ``Links -> dict`` — pairwise scores of a kept subset
    kept_masks : dict ``method -> (L,) bool`` — what each method kept (distributed methods,
        centralized baselines, the oracle of :func:`pipeline.evaluation.oracle.oracle_cut`)
    graph : AssociationGraph or None — the graph of ``links``, when the caller has it

    Returns
    -------
    dict ``method ->`` good cut, spurious cut, spurious links inside the input's conflictive
    sets, spurious left there, links in those sets
    (:func:`pipeline.evaluation.oracle.resolution_scores`) and ``pairwise_f1`` of the result.
    """
    from pipeline.evaluation.oracle import links_in_conflictive_sets, resolution_scores

    in_sets = links_in_conflictive_sets(m, links, graph=graph)  # one input for every method
    return {name: {**resolution_scores(m, links, good, kept, in_sets=in_sets),
                   "pairwise_f1": pairwise(links.subset(kept))["f1"]}
            for name, kept in kept_masks.items()}


def matching_section(matches: list) -> dict:
    """The report's ``matching`` section: links, putative matches and empty reason per edge."""
    return {"edges": [{"i": p.i, "j": p.j, "links": int(len(p.pairs)),
                       "putative": int(p.n_putative), "reason": p.reason} for p in matches]}


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
    if fusion.get("enabled") is False:  # not run: no count of its cuts to show
        lines.append(f"| fusion | not run ({fusion.get('reason', 'disabled')}) |")
    elif "cut_links" in fusion:
        lines.append(f"| links cut by fusion (fusion-outlier) | {fusion['cut_links']} |")
    if fusion.get("robot_sigma_px"):
        sig = " ".join("–" if x is None else f"{x:.2f}" for x in fusion["robot_sigma_px"])
        how = "measured, floor" if fusion.get("noise") == "measured" else "fixed"
        lines.append(f"| fusion keypoint noise per robot [px] ({how} "
                     f"{fusion.get('sigma_px', 1.0):g}) | {sig} |")
    if "rounds" in fusion:
        settled = {True: "stop rule", False: "round cap"}.get(fusion.get("settled"), "fixed")
        if fusion.get("consensus") == "exact":
            settled = "exact flood" if fusion.get("settled") else "exact flood, round cap"
        lines.append(f"| fusion rounds (max-c + consensus, {settled}) | {fusion['rounds']} "
                     f"({fusion.get('maxc_rounds', 0)} + {fusion.get('consensus_rounds', 0)}) |")
        lines.append(f"| fusion messages / bytes | {fusion.get('messages', 0)} / "
                     f"{fusion.get('bytes', 0)} |")
    if "links_cut_robot_lost" in faults:
        lines.append(f"| links cut to lost robots (robot-lost) | {faults['links_cut_robot_lost']} |")
    return "\n".join(lines) + "\n"


_MAPPING_ROWS = (("Registered images", "registered_images"), ("Points", "points"),
                 ("Mean track length", "mean_track_length"),
                 ("Mean reprojection error [px]", "mean_reprojection_error"))


def mapping_markdown(before, after) -> str:
    """Markdown rows of two incremental reconstructions (:class:`pipeline.colmap.MappingSummary`)."""
    return mapping_summaries_markdown(before.summary(), after.summary())


def mapping_summaries_markdown(b: dict, a: dict) -> str:
    """:func:`mapping_markdown` of the two reconstructions' summaries (``MappingSummary.
    summary()``, as a photo run's ``report.json`` holds them under ``triangulation``)."""
    rows = _MAPPING_ROWS
    lines = ["", "| Reconstruction | before | after |", "|---|---:|---:|"]
    # a mean over no point is no figure (None in the summary), not a perfect 0
    lines += [f"| {label} | {NOT_DEFINED if b[key] is None else b[key]} | "
              f"{NOT_DEFINED if a[key] is None else a[key]} |" for label, key in rows]
    return "\n".join(lines) + "\n"


def images_report_markdown(report: dict) -> str:
    """The markdown of a photo run's report (``run-images``): :func:`report_markdown`, the
    reconstructions before and after cleaning (``triangulation``) and the warnings
    (``flags``); read from ``report`` alone, so the run and a reader of its ``report.json``
    (:mod:`viz.saved_run`) show the same text."""
    from pipeline.evaluation.flags import flags_markdown

    md = report_markdown(report)
    tri = report.get("triangulation")
    if isinstance(tri, dict) and all(
            isinstance(tri.get(k), dict) and all(key in tri[k] for _, key in _MAPPING_ROWS)
            for k in ("before", "after")):
        md += mapping_summaries_markdown(tri["before"], tri["after"])
    flags = report.get("flags")
    if isinstance(flags, list) and all(
            isinstance(f, dict) and all(k in f for k in ("flag", "message", "likely_cause"))
            for f in flags):
        md += flags_markdown(flags)
    return md


def track_gt_points(all_gt: np.ndarray, tri) -> np.ndarray:
    """Ground-truth point of each triangulated track (medoid of its observations' points)."""
    from pipeline.evaluation.triangulation import medoids

    pts = medoids(all_gt, [t for t, ok in zip(tri.track_features, tri.ok, strict=True) if ok])
    return pts[np.isfinite(pts).all(axis=1)]


def fused_point_errors(views, feats, resolved_links: Links, fused_points: np.ndarray,
                       fused_track_ids: np.ndarray, gt_points: list,
                       solved_tracks: dict | None = None,
                       fused_track_features: list | None = None) -> dict:
    """Fused landmarks against ground truth and against pycolmap on the same tracks.

    Fusion runs on the links kept by resolution; ``fused_track_ids`` number the track of
    those links that holds each fused landmark like
    :func:`pipeline.association.association_sets` on them (smallest feature id), so the
    pycolmap triangulation of the same links gives the point to compare with.
    ``fused_track_features``: the global feature ids each landmark was fused from
    (:attr:`pipeline.stages.CleaningResult.fused_track_features`), whose ground truth it is
    compared with (default: the features of its track of ``resolved_links``; they differ
    when a robot took no part in fusion).
    ``solved_tracks``: the tracks the run has triangulated already
    (:func:`pipeline.evaluation.triangulation.triangulate_tracks`).
    """
    from pipeline.evaluation.triangulation import medoids, triangulate_tracks

    tri = triangulate_tracks(views, feats, resolved_links, solved_tracks=solved_tracks)
    tracks = tri.track_features
    all_gt = np.concatenate(gt_points) if gt_points else np.zeros((0, 3))
    ids = np.asarray(fused_track_ids, dtype=np.int64)
    pts = np.asarray(fused_points, dtype=np.float64).reshape(-1, 3)
    if fused_track_features is not None and len(fused_track_features) != len(ids):
        raise ValueError("fused_point_errors: one feature set per fused landmark")
    gt_track = medoids(all_gt, [tracks[k] for k in ids])  # what pycolmap triangulated
    gt = gt_track if fused_track_features is None else \
        medoids(all_gt, [np.asarray(g, dtype=np.int64) for g in fused_track_features])
    err_gt = np.linalg.norm(pts - gt, axis=1)
    err_gt = err_gt[np.isfinite(err_gt)]
    ok = tri.ok[ids]
    err_colmap = np.linalg.norm(pts[ok] - tri.xyz[ids[ok]], axis=1)
    err_colmap_gt = np.linalg.norm(tri.xyz[ids[ok]] - gt_track[ok], axis=1)
    err_colmap_gt = err_colmap_gt[np.isfinite(err_colmap_gt)]

    def med(a):
        return float(np.median(a)) if len(a) else None

    return {"fused_points": int(len(pts)),
            "median_error_vs_ground_truth": med(err_gt),
            "p90_error_vs_ground_truth": float(np.percentile(err_gt, 90)) if len(err_gt) else None,
            "median_pycolmap_error_vs_ground_truth": med(err_colmap_gt),
            "median_distance_to_pycolmap": med(err_colmap)}
