"""The pipeline's one stage chain, used by every command (docs/DESIGN.md "Data flow").

Stages, each a function here: :func:`extract_and_match` (features, then matching on the
communication edges only), :func:`consistency_stage` (Aragüés et al., Sec. III detection and
a resolution rule of :mod:`pipeline.consistency.rules` by message passing, by default its
``DEFAULT_RESOLUTION``, with the network's faults),
:func:`fusion_stage` (Montijano et al., robust distributed fusion by dynamic voting) and
:func:`clean_association` (consistency then fusion, on any input, rendered or real). Every
decision about a link is written to one :class:`~pipeline.types.LinkLedger`.

The chain does not know who runs it: the runners of :mod:`pipeline.runs` chain these stages
(or hand the job to a team of robot processes) and write the run folders.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.association import camera_offsets, conflictive_links
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule
from pipeline.faults import FaultConfig
from pipeline.progress import StageTimer
from pipeline.types import LinkLedger, Links, View

__all__ = ["CleaningResult", "merge_radius_for", "check_merge_radius", "budget_line", "extract_and_match",
           "evidence_inputs", "consistency_stage", "ledger_from_consistency", "fusion_stage",
           "fused_tracks", "posed_views", "fusion_on_reconstruction", "clean_association"]


@dataclass
class CleaningResult:
    """What the consistency and fusion stages produced besides the per-link decisions.

    Attributes
    ----------
    ledger : LinkLedger — every link and what the stages decided for it
    resolution_stats : dict — :attr:`ConsistencyResult.stats` of the consistency stage
    fusion_stats : dict — what fusion did, or ``enabled: False`` with the reason it did not run
    fused_points : ndarray, (F, 3) or None — fused landmark of each fused track
    fused_track_ids : ndarray, (F,) or None — track of the links the consistency stage kept
        (association set, numbered as :func:`pipeline.fusion.landmarks.tracks_of` numbers
        them on every camera's features) that holds each fused landmark
    fused_track_features : list of (k,) int arrays or None — global feature ids (camera
        offsets of every camera's features) of the observations each fused landmark was fused
        from: its track as the robots that took part in fusion held it
    faults : dict or None — the report's ``faults`` section when faults were injected
    track_labels : ndarray, (m_total,) or None — each robot's own name for the track of each
        of its features (``ConsistencyResult.track_label``), what fusion's tracks come from
    """

    ledger: LinkLedger
    resolution_stats: dict
    fusion_stats: dict = field(default_factory=dict)
    fused_points: np.ndarray | None = None
    fused_track_ids: np.ndarray | None = None
    fused_track_features: list | None = None
    faults: dict | None = None
    track_labels: np.ndarray | None = None


def merge_radius_for(resolution: str, merge_radius: float | None) -> float:
    """The keypoint merge radius: as given, else the rule's own (``merge_radius_px`` of
    :mod:`pipeline.consistency.rules`: the evidence rule's is the ground-truth tolerance of a
    good link, 2 px, so that two keypoints that would both be "good" for one point are not
    kept as two features of one camera, Def. 2.4), else (a rule without its own, e.g.
    ``paper``, Alg. 1) the co-location radius of :mod:`pipeline.matching.features`.

    Raises
    ------
    InputError
        A negative or non-finite radius.
    """
    from pipeline.errors import InputError
    from pipeline.matching.features import MERGE_RADIUS_PX

    if merge_radius is None:
        own = get_rule(resolution).merge_radius_px
        return MERGE_RADIUS_PX if own is None else own
    _refuse_non_number(merge_radius)
    if not np.isfinite(merge_radius) or merge_radius < 0:
        raise InputError(f"--merge-radius {merge_radius}: expected pixels >= 0 (0 merges nothing)")
    return float(merge_radius)


def _refuse_non_number(merge_radius) -> None:
    """InputError unless ``merge_radius`` is a real number (text failed with numpy's "ufunc
    'isfinite' not supported", ``True`` was read as 1 px)."""
    from pipeline.errors import InputError
    from pipeline.validate import is_number

    if not is_number(merge_radius):
        raise InputError(f"--merge-radius {merge_radius!r}: expected a number of pixels >= 0 "
                         "(0 merges nothing), or None for the rule's")


def check_merge_radius(merge_radius: float | None, sizes, what: str) -> None:
    """Refuse a given ``--merge-radius`` (negative, not finite, or wider than the shorter side
    of the smallest image: keypoints of one image would be merged across the whole image, into
    one or two features) before the features are extracted; ``None`` (the default) passes.

    ``sizes``: the ``(width, height)`` of the images; ``what``: what they are, for the
    message (``'the rendered images'``, ``'the photographs as loaded'``).

    Raises
    ------
    InputError
        The radius and the range allowed, ``0`` to the shorter side.
    """
    from pipeline.errors import InputError
    from pipeline.validate import shown

    if merge_radius is None:
        return
    _refuse_non_number(merge_radius)
    side = min(min(int(w), int(h)) for w, h in sizes)
    if not np.isfinite(merge_radius) or not 0 <= merge_radius <= side:
        raise InputError(f"--merge-radius {shown(merge_radius)}: expected pixels from 0 (merges "
                         f"nothing) to {side}, the shorter side of {what}")


def photo_merge_radius(method: str, resolution: str, merge_radius: float | None) -> float:
    """The merge radius of a photo run: as given, else COLMAP's SIFT merges only co-located
    orientations (:data:`pipeline.matching.features.MERGE_RADIUS_PX`, as COLMAP keeps distinct
    DoG extrema apart; ``pipeline.runs.images`` measured why), else the rule's own
    (:func:`merge_radius_for`)."""
    from pipeline.matching.features import COLMAP_SIFT, MERGE_RADIUS_PX

    if merge_radius is None and method == COLMAP_SIFT:
        return MERGE_RADIUS_PX
    return merge_radius_for(resolution, merge_radius)

def budget_line(views: list[View], max_features: int | None, method: str = "sift") -> str:
    """The feature budget as the stage line says it: ``2000 per image``, or with budgets
    scaled with each image (``max_features=None``) the numbers, e.g. ``3300 per image (2000
    per 640x480 pixels, from 2000 to 8192)`` or ``2000-8192 per image (…)`` for mixed sizes.

    Examples
    --------
    >>> import numpy as np
    >>> budget_line([View("a", np.zeros((640, 800)), np.eye(3))] * 6, None)
    '3333 per image (2000 per 640x480 pixels, from 2000 to 8192)'
    >>> budget_line([View("a", np.zeros((240, 320)), np.eye(3))], None)  # not 500: the floor
    '2000 per image (2000 per 640x480 pixels, from 2000 to 8192)'
    >>> budget_line([], 2000)
    '2000 per image'
    >>> budget_line([], 300, "colmap-sift")
    "300 per image (COLMAP's budget, by whole scale levels: a few more locations may stay)"
    """
    from pipeline.matching.features import (
        BASE_FEATURES,
        COLMAP_SIFT,
        MAX_PHOTO_FEATURES,
        photo_max_features,
    )

    if method == COLMAP_SIFT:  # a location with two orientations gives two features
        return (f"{max_features or MAX_PHOTO_FEATURES} per image (COLMAP's budget, by whole "
                f"scale levels: a few more locations may stay)")
    if max_features is not None:
        return f"{max_features} per image"
    budgets = sorted({photo_max_features(v.image.shape[1], v.image.shape[0]) for v in views})
    span = "-".join(str(b) for b in {budgets[0]: 0, budgets[-1]: 0}) if budgets else "?"
    return (f"{span} per image ({BASE_FEATURES} per 640x480 pixels, from {BASE_FEATURES} to "
            f"{MAX_PHOTO_FEATURES})")


def extract_and_match(views: list[View], comm_edges, method: str,
                      max_features: int | None, timer: StageTimer, *, ratio: float = 0.8,
                      threshold_px: float | None = 1.0, merge_radius: float | None = None,
                      contrast_threshold: float | None = None, rootsift: bool = False,
                      budget_after_merge: bool = False,
                      matcher: str = "opencv") -> tuple[list, list, Links]:
    """Features of every camera, then matching on the communication edges only.

    ``ratio`` (Lowe ratio test) and ``threshold_px`` (epipolar RANSAC inlier threshold) go to
    :func:`pipeline.matching.pairs.match_edges`; keypoints of one image closer than
    ``merge_radius`` pixels are merged (``None``: :data:`pipeline.matching.features.MERGE_RADIUS_PX`);
    ``contrast_threshold``, ``rootsift`` and ``budget_after_merge`` go to
    :func:`pipeline.matching.features.extract`. ``max_features=None`` and ``threshold_px=None`` scale
    with each image's size (:func:`pipeline.matching.features.photo_max_features`,
    :func:`pipeline.matching.pairs.photo_threshold_px`). ``comm_edges`` may be a callable
    ``features -> edges`` (a graph chosen from the features, e.g. ``knn:K`` by image
    similarity). ``matcher`` picks OpenCV's or COLMAP's pair matching
    (:data:`pipeline.matching.pairs.MATCHERS`).

    Returns ``(features, matches, links)``: per-camera Features, per-edge PairMatches and all
    links (``Links.from_matches``).
    """
    from pipeline.matching.features import MERGE_RADIUS_PX, extract_all
    from pipeline.matching.pairs import match_edges

    radius = MERGE_RADIUS_PX if merge_radius is None else merge_radius
    with timer.stage("features", f"{method}, at most {budget_line(views, max_features, method)}"):
        feats = extract_all(views, method, max_features, radius,
                            contrast_threshold=contrast_threshold, rootsift=rootsift,
                            budget_after_merge=budget_after_merge)
        timer.note(f"features per camera: {[len(f) for f in feats]}")
    if callable(comm_edges):
        comm_edges = comm_edges(feats)
    with timer.stage("matching", f"{len(comm_edges)} communication edges"):
        matches = match_edges(feats, views, comm_edges, ratio=ratio, threshold_px=threshold_px,
                              matcher=matcher)
        links = Links.from_matches(matches)
        timer.note(f"{len(links)} links")
    return feats, matches, links


def evidence_inputs(views: list[View], features: list, links: Links, matches=None) -> dict:
    """Keyword arguments of ``resolve_conflicts`` for a rule that needs evidence (the evidence
    rule, :mod:`pipeline.consistency.rules`): each link's local
    weight (:mod:`pipeline.matching.link_evidence`; from ``links.quality`` without ``matches``), each
    robot's keypoints and, where every pose is known, its projection ``K [R | t]``."""
    from pipeline.matching.link_evidence import LinkEvidence, link_evidence

    ev = link_evidence(matches, links, views, features) if matches is not None \
        else LinkEvidence.from_quality(links)
    poses = all(v.R is not None and v.t is not None for v in views)
    return dict(link_weight=ev.weight, keypoints=[f.keypoints for f in features],
                projections=[v.K @ np.c_[v.R, v.t] for v in views] if poses else None)


def consistency_stage(features_per_camera, comm_edges, links: Links,
                      faults: FaultConfig | None = None, *,
                      resolution: str = DEFAULT_RESOLUTION,
                      evidence: dict | None = None):
    """The consistency stage once: detection (Sec. III) and resolution (Alg. 1, or the
    evidence rule of :mod:`pipeline.consistency.evidence`) until conflict-free, on a faulty
    network when ``faults`` switch one on.

    Parameters
    ----------
    features_per_camera : (n,) int
    comm_edges : (E, 2) int or None — ``None``: cameras sharing a link are neighbours
    links : Links, (L,)
    faults : FaultConfig or None
    resolution : a rule of :mod:`pipeline.consistency.rules` (``paper``, ``evidence``, ...;
        default its ``DEFAULT_RESOLUTION``)
    evidence : dict or None — for a rule that needs evidence: ``link_weight``, ``keypoints``,
        ``projections`` for ``resolve_conflicts`` (:func:`evidence_inputs`)

    Returns
    -------
    (ConsistencyResult, dict or None)
        The result and, with faults on, the report's ``faults`` section
        (:func:`pipeline.faults.fault_report`), which compares with the same input on a
        fault-free network (a second run, for the extra rounds and messages).

    Raises
    ------
    InputError
        Links break Assumptions 2.1–2.3 or join cameras that are not neighbours, a crash
        names a robot that does not exist, or the faulty run would take too long
        (:func:`pipeline.faults.check_simulated_work`).
    """
    from pipeline.consistency import resolve_conflicts

    # counts as resolve_conflicts checks them: a cast to int64 read 1.5 features as 1
    m = np.diff(camera_offsets(features_per_camera))
    kw = dict(resolution=resolution, **(evidence or {}))
    if faults is None or not faults.any:
        return resolve_conflicts(m, comm_edges, links, **kw), None
    from pipeline.commgraph import comm_edges_for
    from pipeline.faults import check_simulated_work, fault_report

    edges = comm_edges if comm_edges is not None else comm_edges_for(m, links, None)
    check_simulated_work(len(m), edges, faults, m, links)
    result = resolve_conflicts(m, comm_edges, links, faults.network_options(edges, len(m)),
                               protocol=faults.protocol_options(), **kw)
    # the fault-free reference runs the rule the faulty run ran (on a faulty network a rule
    # that is not fault-tolerant gives way to Alg. 1): the difference is the faults' alone
    from pipeline.consistency.rules import DEFAULT_RESOLUTION, rule_for_network

    ran = rule_for_network(resolution or DEFAULT_RESOLUTION, True).name
    section = fault_report(faults, result, resolve_conflicts(m, comm_edges, links,
                                                             **dict(kw, resolution=ran)))
    section["fault_free_resolution"] = ran
    return result, section


def ledger_from_consistency(result, conflictive_before: np.ndarray | None = None) -> LinkLedger:
    """A :class:`LinkLedger` of the consistency stage's decisions (``ConsistencyResult``)."""
    return LinkLedger(result.links, np.where(result.deleted, "deleted", "kept"),
                      result.reason, result.round, result.iteration, result.case,
                      conflictive_before=conflictive_before)


def fusion_stage(ledger: LinkLedger, views: list[View], features: list, comm_edges, *,
                 cameras: np.ndarray | None = None, transport=None,
                 timer: StageTimer | None = None, detail: str = "",
                 track_labels=None):
    """Robust distributed fusion (Montijano et al., dynamic voting) of the kept links among
    ``cameras``; the links with exactly one end voted out are cut as ``fusion-outlier`` in
    ``ledger``, and those between two outliers that cannot be one point (an outlier leaves
    its landmark: :mod:`pipeline.fusion.landmarks`).

    ``cameras`` (default all) are the robots that take part: they need a pose in ``views``.
    ``track_labels`` (``CleaningResult.track_labels``): the robots' own track names, from
    which the tracks are formed (default: a union-find over the kept links).
    The others act as crashed robots: their links and comm edges are left out, and links to
    them stay as the consistency stage left them. ``transport`` (a
    :class:`~pipeline.transport.Transport` over the ``cameras`` in their order, or None) is
    the network the fusion messages travel on (:func:`pipeline.fusion.landmarks.fuse_tracks`).

    Returns
    -------
    (FusionResult, int) — the fusion result (on the cameras renumbered ``0..k-1``) and the
    number of links it cut.
    """
    from pipeline.fusion.landmarks import fuse_tracks

    timer = timer or StageTimer(verbose=False)
    n = len(views)
    reg = np.arange(n, dtype=np.int64) if cameras is None else np.asarray(cameras, np.int64)
    if transport is not None and transport.n != len(reg):
        raise ValueError("fusion_stage: the transport must be over the cameras taking part")
    new = np.full(n, -1, dtype=np.int64)
    new[reg] = np.arange(len(reg))
    links = ledger.links
    kept_idx = np.flatnonzero(ledger.kept)
    ci, cj = new[links.cam_i[kept_idx]], new[links.cam_j[kept_idx]]
    sub_idx = kept_idx[(ci >= 0) & (cj >= 0)]
    sub_links = Links(new[links.cam_i[sub_idx]], links.feat_i[sub_idx],
                      new[links.cam_j[sub_idx]], links.feat_j[sub_idx], links.quality[sub_idx])
    e = new[np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)]
    with timer.stage("fusion", "robust distributed fusion by dynamic voting" + detail):
        labels = None
        if track_labels is not None:
            off = np.concatenate([[0], np.cumsum([len(f) for f in features])])
            labels = np.concatenate([np.asarray(track_labels)[off[k]:off[k + 1]] for k in reg])
        fr = fuse_tracks([views[k] for k in reg], [features[k] for k in reg], sub_links,
                         e[(e >= 0).all(axis=1)], transport=transport,
                         track_labels=labels)
        cut = sub_idx[np.asarray(fr.cut_links, dtype=bool)]
        ledger.cut(cut, "fusion-outlier", int(fr.stats.get("rounds", -1)))
        timer.note(f"{len(cut)} links cut as fusion outliers")
    return fr, int(len(cut))


def fused_tracks(fr, features_per_camera, links: Links,
                 cameras: np.ndarray | None = None) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each fused landmark of :func:`fusion_stage`'s result ``fr`` (on ``cameras`` renumbered
    ``0..k-1``) in the numbering of every camera: the track of ``links`` (the kept links
    fusion started from, all cameras) that holds it and the global feature ids it was fused
    from.

    Returns
    -------
    (track_ids (F,), features: list of F sorted int arrays) — ``track_ids`` numbered as
    :func:`pipeline.fusion.landmarks.tracks_of` numbers them on ``links``; a crashed robot
    can leave two fused landmarks in one track of ``links`` (it joined them).
    """
    from pipeline.fusion.landmarks import tracks_of

    m = np.asarray(features_per_camera, dtype=np.int64)
    off = np.concatenate([[0], np.cumsum(m)])
    reg = np.arange(len(m), dtype=np.int64) if cameras is None else np.asarray(cameras, np.int64)
    n_points = len(fr.points)
    if n_points == 0:
        return np.zeros(0, np.int64), []
    gid = off[reg[np.asarray(fr.obs_cam, np.int64)]] + np.asarray(fr.obs_feat, np.int64)
    point = np.asarray(fr.obs_point, np.int64)
    order = np.lexsort((gid, point))
    gid, point = gid[order], point[order]
    keep = point >= 0
    groups = np.split(gid[keep], np.searchsorted(point[keep], np.arange(1, n_points)))
    track_of, _ = tracks_of(m, links)
    return np.array([track_of[g[0]] for g in groups], dtype=np.int64), groups


def posed_views(views: list[View], poses: dict) -> list[View]:
    """Copies of ``views`` with ``R, t`` (and the refined ``K``) of those named in ``poses``
    (:func:`pipeline.colmap.registered_poses`); the others unchanged."""
    import dataclasses

    out = []
    for v in views:
        if v.name in poses:
            R, t, K = poses[v.name]
            out.append(dataclasses.replace(v, R=R, t=t, K=K))
        else:
            out.append(v)
    return out


def fusion_on_reconstruction(ledger: LinkLedger, views: list[View], features: list, comm_edges,
                             reconstruction, *, timer: StageTimer | None = None,
                             track_labels=None):
    """:func:`fusion_stage` among the cameras ``reconstruction`` (pycolmap) registered, on its
    poses and refined cameras.

    The poses come with a lens model (e.g. SIMPLE_RADIAL): fusion's pinhole projections see
    each keypoint where the pinhole ``K`` of its camera would have seen it
    (:func:`pipeline.colmap.undistorted_keypoints`). A camera the reconstruction did not
    register cannot form a local landmark estimate, so it takes no part (as a crashed robot);
    its links stay as the consistency stage left them.

    Returns
    -------
    (FusionResult or None, int, ndarray) — the fusion result (None when fewer than two
    cameras are registered: nothing runs), the number of links it cut, the registered
    cameras' indices.
    """
    import dataclasses

    from pipeline import colmap

    poses = colmap.registered_poses(reconstruction)
    reg = np.array([k for k, v in enumerate(views) if v.name in poses], dtype=np.int64)
    if len(reg) < 2:
        return None, 0, reg
    features = [dataclasses.replace(f, keypoints=colmap.undistorted_keypoints(
        reconstruction, v.name, f.keypoints).astype(np.float32))
        for v, f in zip(views, features, strict=True)]
    fr, n_cut = fusion_stage(ledger, posed_views(views, poses), features, comm_edges,
                             cameras=reg, timer=timer, track_labels=track_labels,
                             detail=f", {len(reg)} of {len(views)} cameras posed")
    return fr, n_cut, reg


def clean_association(views: list[View], features: list, comm_edges: np.ndarray, links: Links,
                      *, fusion: bool = True, timer: StageTimer | None = None,
                      faults: FaultConfig | None = None, resolution: str = DEFAULT_RESOLUTION,
                      matches: list | None = None,
                      max_memory_gb: float | None = None) -> CleaningResult:
    """Consistency (Aragüés et al., Sec. III–IV) then fusion (Montijano et al.) on ``links``.

    ``resolution``: a rule of :mod:`pipeline.consistency.rules`, e.g. ``paper`` (Alg. 1) or
    ``evidence`` (:mod:`pipeline.consistency.evidence`, with the link evidence of ``matches``
    when given, see :func:`evidence_inputs`).

    Fusion needs camera poses; it is skipped (and says so in ``fusion_stats``) without them.
    ``max_memory_gb``: the fusion stage is refused (InputError) when its estimate on the tracks
    the consistency stage named exceeds it (:func:`pipeline.budget.check_fusion_memory`).
    With ``faults`` on, the consistency stage runs on the faulty network (and once more
    fault-free, for the ``faults`` section's extra rounds and messages); a switching topology
    is used by the fusion consensus too.
    """
    timer = timer or StageTimer(verbose=False)
    m = np.array([len(f) for f in features], dtype=np.int64)
    with timer.stage("consistency", f"distributed detection + resolution ({resolution})"):
        conflictive_before = conflictive_links(m, links)
        evidence = evidence_inputs(views, features, links, matches) \
            if get_rule(resolution).needs_evidence else None
        res, fault_section = consistency_stage(m, comm_edges, links, faults,
                                               resolution=resolution, evidence=evidence)
        ledger = ledger_from_consistency(res, conflictive_before)
        timer.note(f"{int(res.deleted.sum())} of {len(links)} links cut in "
                   f"{res.stats.get('iterations')} iteration(s)")
    cleaning = CleaningResult(ledger, dict(res.stats), faults=fault_section,
                              track_labels=res.track_label)
    has_poses = all(v.R is not None and v.t is not None for v in views)
    if not fusion:
        cleaning.fusion_stats = {"enabled": False, "reason": "disabled by option"}
    elif not has_poses:
        cleaning.fusion_stats = {"enabled": False, "reason": "camera poses unknown"}
    else:
        cameras, transport, crashed = None, None, []
        if faults is not None and faults.any:
            # robots crashed during consistency take no part; the others run fusion on the
            # same faulty network, its clock going on (pipeline.fusion.protocol)
            from pipeline.commgraph import comm_edges_for

            edges = comm_edges if comm_edges is not None else comm_edges_for(m, links, None)
            crashed = sorted(int(k) for k in res.stats.get("faults", {}).get("crashed", {}))
            cameras = np.array([i for i in range(len(m)) if i not in crashed], dtype=np.int64)
            start = int(res.stats.get("detection_rounds", 0) + res.stats.get("resolution_rounds", 0)
                        + res.stats.get("closing_rounds", 0))
            transport = faults.fusion_transport(edges, cameras, start)
            comm_edges = edges
        if cameras is not None and len(cameras) == 0:
            cleaning.fusion_stats = {"enabled": False, "reason": "every robot crashed before "
                                                                 "fusion",
                                     "crashed_before_fusion": crashed}
            return cleaning
        if max_memory_gb is not None:
            from pipeline.budget import check_fusion_memory

            check_fusion_memory(len(m) if cameras is None else len(cameras),
                                cleaning.track_labels, max_memory_gb)
        kept_links = ledger.links.subset(ledger.kept)  # what fusion starts from
        fr, n_cut = fusion_stage(ledger, views, features, comm_edges, timer=timer,
                                 track_labels=cleaning.track_labels, cameras=cameras,
                                 transport=transport)
        stats = dict(fr.stats)
        if cameras is not None:
            # the fusion stage numbers the taking-part robots 0..k-1: report team ids
            stats["crashed"] = [int(cameras[i]) for i in stats.get("crashed", [])]
            stats["crashed_before_fusion"] = crashed
            stats["robots_lost"] = {str(int(cameras[int(k)])): [int(cameras[j]) for j in v]
                                    for k, v in stats.get("robots_lost", {}).items()}
            # per-robot figures: one entry per robot of the team, None for one that took
            # no part
            for key in ("robot_sigma_px", "noise_residuals"):
                if key in stats:
                    per_robot = [None] * len(m)
                    for k, v in zip(cameras.tolist(), stats[key], strict=True):
                        per_robot[k] = v
                    stats[key] = per_robot
            if fault_section is not None:
                # a crash the consistency stage did not reach may have hit fusion
                later = fault_section.get("crashes_not_reached", {})
                fault_section["crashed_during_fusion"] = {
                    str(r): later[str(r)] for r in stats["crashed"] if str(r) in later}
                fault_section["crashes_not_reached"] = {
                    k: v for k, v in later.items()
                    if k not in fault_section["crashed_during_fusion"]}
        cleaning.fusion_stats = {"enabled": True, **stats, "observations_cut_links": n_cut}
        cleaning.fused_points = np.asarray(fr.points)
        # fusion numbered its tracks on the robots that took part: number them on all
        cleaning.fused_track_ids, cleaning.fused_track_features = fused_tracks(
            fr, m, kept_links, cameras)
    return cleaning


