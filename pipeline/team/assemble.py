"""What the observer makes of a team's published results: links, decisions, fusion, options.

The robots compute everything (:mod:`pipeline.team.robot`); the observer here only reads what
they published (the ``zenoh`` transport of :mod:`pipeline.runs.transports` launches them) and
turns it into what the run outputs of docs/DESIGN.md are made of: the links of every comm edge
(from the matches the robots hold, in the comm-graph order the simulator uses), the decision
on every link (:func:`pipeline.consistency.linklog.merge_link_logs` over the robots' own
logs), and the report. Evaluation against ground truth is centralized checking code: it
renders the formation itself, as ``run-formation`` does, and never feeds anything back.

The robots resolve by Alg. 1 or by the evidence rule, as the simulator does
(:func:`pipeline.team.robot.robot_resolution`). On a rendered formation they then run fusion
themselves (:mod:`pipeline.fusion.robot`); the observer cuts the links any robot cut as
``fusion-outlier`` (:func:`fusion_of_team`) and reports the stage from their counters.
``run-images`` over zenoh runs no fusion (its poses come from a reconstruction of every
photograph at once, which no robot holds).
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.result import ConsistencyResult, result_from_logs
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule
from pipeline.types import Links, PairMatches

__all__ = ["team_options", "links_of_team", "consistency_of_team", "fusion_of_team",
           "FUSION_SKIPPED", "EXCHANGE_KINDS", "FUSION_KINDS", "stage_of_kind"]

#: message kinds of the feature exchange before consistency (pipeline.team.robot) and of
#: fusion (pipeline.fusion.robot, with the reliable fusion's empty rounds ``fusion-tick``);
#: every other kind is the consistency stage's (detection, each resolution rule's own —
#: the evidence rule's ``bundle``, the sync rule's ``sync-*`` —, the reliable channel's)
EXCHANGE_KINDS = ("features", "matches", "counts", "lossy", "shared-links")
FUSION_KINDS = ("fusion-setup", "fusion-maxc", "fusion", "fusion-cut", "fusion-tick")


def stage_of_kind(kind: str) -> str:
    """``exchange``, ``consistency`` or ``fusion``: the stage a message kind belongs to."""
    return ("exchange" if kind in EXCHANGE_KINDS else "fusion" if kind in FUSION_KINDS
            else "consistency")
FUSION_SKIPPED = {"enabled": False, "reason": "fusion does not run over the zenoh transport "
                  "for photographs (their poses come from a reconstruction of all of them)"}


def team_options(features: str = "sift", max_features: int | None = 2000, faults=None,
                 round_timeout_s: float | None = None,
                 merge_radius: float | None = None,
                 resolution: str = DEFAULT_RESOLUTION, fusion: bool = False,
                 **feature_options) -> dict:
    """Team options from command-line settings; only ``--drop-prob`` is a zenoh fault.

    ``feature_options``: ``contrast_threshold``, ``rootsift``, ``budget_after_merge``,
    ``threshold_px`` (see :data:`pipeline.team.teamfile.DEFAULT_OPTIONS`). ``round_timeout_s``
    None: not set here, so the team takes the command's ``--round-timeout`` or the default
    (:func:`pipeline.team.launcher.make_team`).

    Raises
    ------
    InputError
        ``--crash``, ``--delay-rounds`` or ``--switching-topology`` (faults of the simulated
        network; over Zenoh kill a robot process instead).
    """
    from pipeline.faults import check_faults_for_transport
    from pipeline.matching.features import MERGE_RADIUS_PX

    opts = {"features": features,
            "max_features": None if max_features is None else int(max_features),
            "merge_radius": float(MERGE_RADIUS_PX if merge_radius is None else merge_radius),
            "resolution": resolution, "fusion": bool(fusion), **feature_options}
    if round_timeout_s is not None:
        opts["round_timeout_s"] = float(round_timeout_s)
    if faults is not None:
        check_faults_for_transport(faults, "zenoh")
        opts["drop_prob"] = float(faults.drop_prob)
        opts["fault_seed"] = int(faults.seed)
    return opts


def _pm_from(i: int, k: int, header: dict, arrays: dict) -> PairMatches | None:
    if f"pairs_{k}" not in arrays:
        return None
    meta = next((m for m in header["matches"] if {m["i"], m["j"]} == {i, k}), None)
    if meta is None:
        return None
    return PairMatches(meta["i"], meta["j"], arrays[f"pairs_{k}"].reshape(-1, 2),
                       arrays[f"ratio_{k}"], arrays[f"eperr_{k}"], int(meta["n_putative"]),
                       meta["reason"])


def links_of_team(team, results: dict) -> tuple[list[PairMatches], Links]:
    """Matches of every comm edge (from whichever end published them) and all links."""
    from pipeline.commgraph import check_comm_edges

    matches = []
    for i, j in check_comm_edges(team.comm_edges, team.n):
        i, j = int(i), int(j)
        pm = None
        for a, b in ((i, j), (j, i)):
            if a in results:
                pm = _pm_from(a, b, *results[a])
                if pm is not None:
                    break
        if pm is None:
            pm = PairMatches(i, j, np.zeros((0, 2), np.int32), np.zeros(0, np.float32),
                             np.zeros(0, np.float32), 0, "both robots lost before publishing")
        matches.append(pm)
    return matches, Links.from_matches(matches)


def _link_keys(cam_i, feat_i, cam_j, feat_j, n: int, M: int) -> np.ndarray:
    return ((cam_i * n + cam_j) * M + feat_i) * M + feat_j


def _counted(heads: dict, stage: str) -> tuple[dict, dict]:
    """Messages and bytes of each kind of ``stage`` (:func:`stage_of_kind`), summed over the
    robots' published counters."""
    kinds = FUSION_KINDS if stage == "fusion" else sorted(
        {k for h in heads.values() for k in h["counters"]["bytes_by_kind"]
         if stage_of_kind(k) == stage})
    msgs = {k: 0 for k in kinds}
    byts = {k: 0 for k in kinds}
    for h in heads.values():
        for k in kinds:
            msgs[k] += h["counters"]["messages_by_kind"].get(k, 0)
            byts[k] += h["counters"]["bytes_by_kind"].get(k, 0)
    return msgs, byts


class _LinkIndex:
    """Maps a robot's link-table rows to the links ``0..L-1`` (reporting only)."""

    def __init__(self, links: Links, n: int, fpc) -> None:
        self.n, self.L = int(n), len(links)
        self.M = int(np.asarray(fpc, dtype=np.int64).max(initial=0)) + 1
        self.key = _link_keys(links.cam_i, links.feat_i, links.cam_j, links.feat_j, n, self.M)
        self.order = np.argsort(self.key)

    def rows(self, i: int, a: dict) -> np.ndarray:
        nbr = a["link_nbr"].astype(np.int64)
        r, s = a["link_r"].astype(np.int64), a["link_s"].astype(np.int64)
        lo = i < nbr
        k = _link_keys(np.where(lo, i, nbr), np.where(lo, r, s), np.where(lo, nbr, i),
                       np.where(lo, s, r), self.n, self.M)
        if not self.L:
            return np.zeros(0, np.int64)
        pos = self.order[np.searchsorted(self.key[self.order], k)]
        if not np.array_equal(self.key[pos], k):
            raise RuntimeError(f"robot {i} published a link that no matching produced")
        return pos


def _team_phases(heads: dict, phases: list) -> list:
    """One robot's phase records with the team's counts where the simulator reports the
    team's (:mod:`pipeline.consistency.engines.driver`): a detection's
    ``conflictive_features`` summed over the robots' own (each robot counts only its
    features), and a resolution's ``conflictive_sets``, the sets the robots rooted
    (``roots``, each set once). Every robot runs the same phases (the termination wave ends
    each phase at all of them), so the records of one phase are those at the same place."""
    out = []
    for k, ph in enumerate(phases):
        ph = dict(ph)
        same = [h["run"]["phases"][k] for h in heads.values()
                if len(h.get("run", {}).get("phases", [])) > k
                and h["run"]["phases"][k].get("phase") == ph.get("phase")
                and h["run"]["phases"][k].get("iteration") == ph.get("iteration")]
        if ph.get("phase") == "detection" and "conflictive_features" in ph:
            ph["conflictive_features"] = int(sum(p.get("conflictive_features", 0)
                                                 for p in same))
        if ph.get("phase") == "resolution" and "roots" in ph:
            ph["conflictive_sets"] = int(sum(p.get("roots", 0) for p in same))
        out.append(ph)
    return out


def consistency_of_team(team, results: dict, links: Links, fpc, killed=()) -> ConsistencyResult:
    """The :class:`ConsistencyResult` of a team run, read from the robots' published logs."""
    n = team.n
    fpc = np.asarray(fpc, dtype=np.int64)
    index = _LinkIndex(links, n, fpc)
    logs = []
    survivors = np.array([i in results for i in range(n)], dtype=bool)
    for i, (_, a) in sorted(results.items()):
        pos = index.rows(i, a)
        logs.append((pos, a["link_alive"].astype(bool), a["deleted_case"],
                     a["deleted_round"], a["deleted_iteration"]))
    comp = np.concatenate([results[i][1]["component"] if i in results
                           else np.full(int(fpc[i]), -1, np.int64) for i in range(n)])
    heads = {i: h for i, (h, _) in results.items()}
    any_run_head = heads[min(heads)] if heads else {}
    any_run = any_run_head.get("run", {})
    msgs, byts = _counted(heads, "consistency")
    lost_by = {}
    for i, h in heads.items():
        for k in h["run"].get("lost_neighbours", []):
            lost_by.setdefault(int(k), []).append(int(i))
    faults = dict(
        # the highest loss any robot injects (a robot's own option may set it alone)
        drop_probability=max(float(team.options_for(i).get("drop_prob", 0.0) or 0.0)
                             for i in range(n)), switching_topology=False,
        dropped=int(sum(h["counters"]["dropped"] for h in heads.values())),
        crashed={int(k): None for k in killed},
        crashes_not_reached={},
        robots_lost={k: sorted(v) for k, v in sorted(lost_by.items())},
        retransmissions=int(sum(h["run"].get("retransmissions", 0) for h in heads.values())),
        acks=int(sum(h["run"].get("acks", 0) for h in heads.values())),
        heartbeats=int(sum(h["run"].get("heartbeats", 0) for h in heads.values())),
        repeated_detections=int(any_run.get("repeated_detections", 0)),
        rounds=int(max((h["counters"]["round"] for h in heads.values()), default=0)))
    stats = dict(
        iterations=int(any_run.get("iterations", 0)),
        detection_rounds=int(any_run.get("detection_rounds", 0)),
        resolution_rounds=int(any_run.get("resolution_rounds", 0)),
        closing_rounds=int(any_run.get("closing_rounds", 0)),
        per_iteration=_team_phases(heads, any_run.get("phases", [])),
        messages=int(sum(msgs.values())), bytes=int(sum(byts.values())),
        messages_by_kind={k: v for k, v in msgs.items() if v},
        bytes_by_kind={k: v for k, v in byts.items() if v},
        max_robot_memory_bytes=int(max((h["peak_memory_bytes"] for h in heads.values()),
                                       default=0)),
        protocol="reliable", resolution=str(any_run_head.get("resolution", "paper")),
        termination="local (termination wave)")
    res = result_from_logs(links, logs, survivors, comp, stats=stats, faults=faults)
    if not get_rule(stats["resolution"]).detection:
        # a rule without detection is one pass, an iteration when it cut anything, as the
        # simulator counts it (engines.driver); a robot's own log counts its Borůvka rounds
        res.stats["iterations"] = int(bool(res.deleted.any()))
    return res


def _fusion_tracks(results: dict, fpc: np.ndarray) -> dict:
    """The stage's tracks and observations from the track names the robots started fusion
    from (``fusion_labels``; a robot that published none holds no observation), counted as
    :func:`pipeline.fusion.landmarks.fuse_tracks` counts them from the same names: a name
    held by two features or more is a track, conflictive when one robot holds it twice."""
    from pipeline.fusion.landmarks import tracks_from_labels

    labels = np.concatenate([results[i][1]["fusion_labels"].astype(np.int64)
                             if i in results and "fusion_labels" in results[i][1]
                             else np.full(int(fpc[i]), -1, np.int64) for i in range(len(fpc))]) \
        if len(fpc) else np.zeros(0, np.int64)
    track_of, T, _ = tracks_from_labels(labels, int(fpc.sum()))
    cam = np.repeat(np.arange(len(fpc)), fpc)
    per = np.zeros((T, len(fpc)), dtype=np.int64)
    sel = track_of >= 0
    np.add.at(per, (track_of[sel], cam[sel]), 1)
    return dict(tracks=int(T), tracks_conflictive=int((per > 1).any(1).sum()),
                observations=int(sel.sum()))


def fusion_of_team(team, results: dict, ledger,
                   fpc) -> tuple[dict, np.ndarray, np.ndarray, list]:
    """Cut in ``ledger`` the links a robot cut in its fusion stage; the stage's figures and
    fused landmarks, read from what the robots published (reporting only).

    A link still kept after consistency is cut as ``fusion-outlier`` when either end's robot
    cut it (one end an outlier observation and the other not, each end told the other's), in the
    team's fusion round count (the largest a robot heard with the termination wave). The fused
    landmark of a track is formed as the simulator forms it
    (:func:`pipeline.fusion.points.fused_points`, from every robot's final estimate); its id
    is the union-find
    track (:func:`pipeline.fusion.landmarks.tracks_of` over the kept links) of its smallest
    feature still in one (a landmark with none, whose links a robot lost during fusion took
    away, is left out of the points returned, not of ``stats``), and its features those the
    robots that published fused it from
    (:attr:`pipeline.stages.CleaningResult.fused_track_features`).

    Returns
    -------
    (stats, points (F, 3), track_ids (F,), features: list of F sorted global feature id arrays)
    """
    from pipeline.fusion.landmarks import tracks_of
    from pipeline.fusion.points import fused_points

    n = team.n
    fpc = np.asarray(fpc, dtype=np.int64)
    off = np.concatenate([[0], np.cumsum(fpc)])
    links = ledger.links
    before = ledger.kept.copy()
    index = _LinkIndex(links, n, fpc)
    cut = np.zeros(len(links), dtype=bool)
    heads = {i: h for i, (h, _) in results.items()}
    rounds = max((int((h.get("fusion") or {}).get("fusion_rounds", 0)) for h in heads.values()),
                 default=0)
    for i, (_, a) in results.items():
        if "fusion_cut" in a:
            cut[index.rows(i, a)[a["fusion_cut"].astype(bool)]] = True
    cut &= before
    ledger.cut(cut, "fusion-outlier", rounds)
    msgs, byts = _counted(heads, "fusion")
    # fused landmarks: every robot's final estimate of every track it observes
    rows = [(i, a) for i, (_, a) in sorted(results.items()) if "fusion_names" in a]
    names = np.unique(np.concatenate([a["fusion_names"] for _, a in rows])) if rows \
        else np.zeros(0, np.int64)
    T = len(names)
    obs = np.zeros((T, n), dtype=bool)
    good = np.zeros((T, n), dtype=bool)
    theta = np.zeros((T, n, 3))
    winner = np.zeros((T, n), dtype=np.int64)
    gid = np.full((T, n), np.iinfo(np.int64).max, dtype=np.int64)
    for i, a in rows:
        b = np.searchsorted(names, a["fusion_names"])
        obs[b, i] = True
        good[b, i] = a["fusion_valid"].astype(bool) & a["fusion_estimated"].astype(bool)
        theta[b, i] = a["fusion_theta"]
        winner[b, i] = a["fusion_winner"]
        gid[b, i] = off[i] + a["fusion_feat"].astype(np.int64)
    edges = np.asarray(team.comm_edges, dtype=np.int64).reshape(-1, 2)
    ne = [np.stack([np.flatnonzero(obs[:, u] & obs[:, v]) * n + u,
                    np.flatnonzero(obs[:, u] & obs[:, v]) * n + v], 1) for u, v in edges]
    ne = np.concatenate(ne) if ne else np.zeros((0, 2), np.int64)
    fusion_heads = [h["fusion"] for h in heads.values() if h.get("fusion")]
    K = int(fusion_heads[0]["hypotheses"]) if fusion_heads else None
    fused = fused_points(ne, good, theta, winner, K)
    pts, has_pt, grp = fused.points, fused.has_point, fused.group
    uf, _ = tracks_of(fpc, links.subset(before))
    # the track of each robot's observation in the kept links (-1: none, e.g. its links to a
    # robot lost during fusion were cut after it fused them)
    big = np.iinfo(np.int64).max
    tr = np.where(gid < off[-1], uf[np.minimum(gid, max(int(off[-1]) - 1, 0))], -1)
    first = np.where(tr >= 0, gid, big).argmin(1) if T else np.zeros(0, np.int64)
    ids = tr[np.arange(T), first] if T else np.zeros(0, np.int64)
    in_track = ids >= 0
    mode = fusion_heads[0].get("consensus", "metropolis") if fusion_heads else None
    # the exact mode floods (no separate max-c rounds); Metropolis: n - 1 max-c rounds first
    maxc = max(n - 1, 0) if mode == "metropolis" else 0
    tracks = _fusion_tracks(results, fpc)
    voted_out = sum(int((a["fusion_estimated"].astype(bool)
                         & ~a["fusion_inlier"].astype(bool)).sum()) for _, a in rows)
    stats = dict(
        enabled=True, transport="zenoh", **tracks, consensus=mode, rounds=int(rounds), maxc_rounds=maxc,
        consensus_rounds=max(int(rounds) - maxc, 0),
        settled=(bool(rounds - maxc < 100) if mode == "metropolis"
                 else not any(h.get("forced", False) for h in fusion_heads)),
        messages=int(sum(msgs.values())), bytes=int(sum(byts.values())),
        messages_by_kind={k: v for k, v in msgs.items() if v},
        bytes_by_kind={k: v for k, v in byts.items() if v},
        # both ends of every observer-graph edge, every round (the simulator's logical count)
        logical_messages=int(2 * len(ne) * rounds),
        setup_messages=int(msgs["fusion-setup"]), setup_bytes=int(byts["fusion-setup"]),
        tracks_fused=int(has_pt.sum()),
        observations_estimated=int(sum(h["estimated"] for h in fusion_heads)),
        observations_voted_out=int(voted_out),
        observations_cut=int(sum(h["outliers"] for h in fusion_heads)),
        links_cut=int(cut.sum()), observations_cut_links=int(cut.sum()),
        tracks_split_winner=int((fused.split & has_pt).sum()),
        max_disagreement=float(np.max(np.where(grp, np.linalg.norm(
            theta - pts[:, None], axis=-1), 0.0))) if has_pt.any() else 0.0,
        hypotheses=int(K or 0),
        **(fusion_heads[0].get("options", {}) if fusion_heads else {}),
        noise=fusion_heads[0].get("noise") if fusion_heads else None,
        # per robot; None: a robot that published no fusion
        robot_sigma_px=[((heads.get(i) or {}).get("fusion") or {}).get("sigma_px")
                        for i in range(n)],
        noise_residuals=[((heads.get(i) or {}).get("fusion") or {}).get("noise_residuals")
                         for i in range(n)],
        retransmissions=int(sum(h.get("retransmissions", 0) for h in fusion_heads)),
        phase_rounds=max((int(h["rounds"]) for h in fusion_heads), default=0),
        robots_lost={str(i): h["lost"] for i, h in sorted(
            (i, (hh.get("fusion") or {})) for i, hh in heads.items()) if h.get("lost")})
    # the landmarks of tracks still in the kept links, each named by the track of its smallest
    # observation still in one
    keep = has_pt & in_track
    groups = [np.sort(gid[b, obs[b]]) for b in np.flatnonzero(keep)]
    return stats, pts[keep], ids[keep], groups
