"""Runs over ``--transport zenoh``: a team of robot processes, then the usual run outputs.

The robots compute everything (:mod:`pipeline.teamrobot`); the observer here only reads what
they published and turns it into the run outputs of docs/DESIGN.md: the links of every comm edge
(from the matches the robots hold, in the comm-graph order the simulator uses), the decision
on every link (:func:`pipeline.consistency.linklog.merge_link_logs` over the robots' own
logs), and the report. Evaluation against ground truth is centralized checking code: it
renders the formation itself, as ``run-formation`` does, and never feeds anything back.

The robots resolve by Alg. 1 or by the evidence rule, as the simulator does
(:func:`pipeline.teamrobot.team_resolution`). On a rendered formation they then run fusion
themselves (:mod:`pipeline.fusion.robot`); the observer cuts the links any robot cut as
``fusion-outlier`` (:func:`fusion_of_team`) and reports the stage from their counters.
``run-images`` over zenoh runs no fusion (its poses come from a reconstruction of every
photograph at once, which no robot holds).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.consistency import DEFAULT_RESOLUTION
from pipeline.consistency.engine import ConsistencyResult
from pipeline.consistency.linklog import merge_link_logs
from pipeline.errors import InputError, TeamError
from pipeline.launcher import launch_team, make_team, team_summary
from pipeline.progress import StageTimer
from pipeline.types import Links, PairMatches

__all__ = ["run_formation_team", "resolve_conflicts_team", "images_team", "team_options",
           "links_of_team", "consistency_of_team"]

CONSISTENCY_KINDS = ("blocks", "final", "request", "reject", "closing", "ack", "heartbeat")
FUSION_KINDS = ("fusion-setup", "fusion-maxc", "fusion", "fusion-cut")
FUSION_SKIPPED = {"enabled": False, "reason": "fusion does not run over the zenoh transport "
                  "for photographs (their poses come from a reconstruction of all of them)"}


def team_options(features: str = "sift", max_features: int | None = 2000, faults=None,
                 round_timeout_s: float = 5.0, merge_radius: float | None = None,
                 resolution: str = DEFAULT_RESOLUTION, fusion: bool = False,
                 **feature_options) -> dict:
    """Team options from command-line settings; only ``--drop-prob`` is a zenoh fault.

    ``feature_options``: ``contrast_threshold``, ``rootsift``, ``budget_after_merge``,
    ``threshold_px`` (see :data:`pipeline.team.DEFAULT_OPTIONS`).

    Raises
    ------
    InputError
        ``--crash``, ``--delay-rounds`` or ``--switching-topology`` (faults of the simulated
        network; over Zenoh kill a robot process instead).
    """
    from pipeline.features import MERGE_RADIUS_PX

    opts = {"features": features,
            "max_features": None if max_features is None else int(max_features),
            "round_timeout_s": float(round_timeout_s),
            "merge_radius": float(MERGE_RADIUS_PX if merge_radius is None else merge_radius),
            "resolution": resolution, "fusion": bool(fusion), **feature_options}
    if faults is not None:
        if faults.crash or faults.switching_topology or faults.delay_rounds:
            raise InputError("--crash, --delay-rounds and --switching-topology are faults of "
                             "the simulated network (--transport sim); over zenoh, kill a "
                             "robot process instead; --drop-prob works on both")
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


def _counted(heads: dict, kinds) -> tuple[dict, dict]:
    """Messages and bytes of each kind, summed over the robots' published counters."""
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


def consistency_of_team(team, results: dict, links: Links, fpc, killed=()) -> ConsistencyResult:
    """The :class:`ConsistencyResult` of a team run, read from the robots' published logs."""
    n = team.n
    L = len(links)
    fpc = np.asarray(fpc, dtype=np.int64)
    index = _LinkIndex(links, n, fpc)
    logs = []
    survivors = np.array([i in results for i in range(n)], dtype=bool)
    for i, (_, a) in sorted(results.items()):
        pos = index.rows(i, a)
        logs.append((pos, a["link_alive"].astype(bool), a["deleted_case"],
                     a["deleted_round"], a["deleted_iteration"]))
    d = merge_link_logs(L, logs)
    comp = np.concatenate([results[i][1]["component"] if i in results
                           else np.full(int(fpc[i]), -1, np.int64) for i in range(n)])
    heads = {i: h for i, (h, _) in results.items()}
    any_run_head = heads[min(heads)] if heads else {}
    any_run = any_run_head.get("run", {})
    msgs, byts = _counted(heads, CONSISTENCY_KINDS)
    lost_by = {}
    for i, h in heads.items():
        for k in h["run"].get("lost_neighbours", []):
            lost_by.setdefault(int(k), []).append(int(i))
    both_alive = survivors[links.cam_i] & survivors[links.cam_j] if L else np.zeros(0, bool)
    faults = dict(
        drop_probability=float(team.options.get("drop_prob", 0.0)), switching_topology=False,
        dropped=int(sum(h["counters"]["dropped"] for h in heads.values())),
        crashed={int(k): None for k in killed},
        crashes_not_reached={},
        robots_lost={k: sorted(v) for k, v in sorted(lost_by.items())},
        links_cut_robot_lost=int(d["robot_lost"].sum()),
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
        per_iteration=any_run.get("phases", []),
        messages=int(sum(msgs.values())), bytes=int(sum(byts.values())),
        messages_by_kind={k: v for k, v in msgs.items() if v},
        bytes_by_kind={k: v for k, v in byts.items() if v},
        max_robot_memory_bytes=int(max((h["peak_memory_bytes"] for h in heads.values()),
                                       default=0)),
        asymmetric_links=int(((d["ends_deleted"] == 1) & both_alive).sum()),
        deleted_links=int(d["deleted"].sum()), protocol="reliable", survivors=survivors,
        resolution=str(any_run_head.get("resolution", "paper")),
        termination="local (termination wave)", faults=faults)
    return ConsistencyResult(links=links, deleted=d["deleted"], reason=d["reason"],
                             iteration=d["iteration"], round=d["round"], case=d["case"],
                             component=comp, stats=stats)


def fusion_of_team(team, results: dict, ledger, fpc) -> tuple[dict, np.ndarray, np.ndarray]:
    """Cut in ``ledger`` the links a robot cut in its fusion stage; the stage's figures and
    fused landmarks, read from what the robots published (reporting only).

    A link still kept after consistency is cut as ``fusion-outlier`` when either end's robot
    cut it (its own outlier observation, or its neighbour's as the neighbour told it), in the
    team's fusion round count (the largest a robot heard with the termination wave). The fused
    landmark of a track is formed as :func:`pipeline.fusion.landmarks.fuse_tracks` forms it:
    the final estimates of the largest connected group of robots with a valid estimate, among
    them those that picked the group's most common winner, averaged; its id is the union-find
    track (:func:`pipeline.fusion.landmarks.tracks_of` over the kept links) of its smallest
    feature.

    Returns
    -------
    (stats, points (F, 3), track_ids (F,))
    """
    from scipy.sparse.csgraph import connected_components

    from pipeline.fusion.landmarks import tracks_of

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
    msgs, byts = _counted(heads, FUSION_KINDS)
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
    import scipy.sparse as sp

    ncomp, lab = connected_components(sp.csr_matrix(
        (np.ones(len(ne)), (ne[:, 0], ne[:, 1])), shape=(T * n, T * n)), directed=False)
    lab = lab.reshape(T, n)
    size = np.bincount(lab[good], minlength=ncomp)
    score = np.where(good, size[lab], -1)
    best_node = np.argmax(score, axis=1) if T else np.zeros(0, np.int64)
    has_pt = score[np.arange(T), best_node] > 0
    grp = good & (lab == lab[np.arange(T), best_node][:, None]) & has_pt[:, None]
    K = int(winner.max(initial=0)) + 1
    wcount = np.zeros((T, K), dtype=np.int64)
    gb, gi = np.nonzero(grp)
    np.add.at(wcount, (gb, winner[gb, gi]), 1)
    grp &= winner == np.argmax(wcount, axis=1)[:, None]
    cnt = grp.sum(1)
    pts = (theta * grp[..., None]).sum(1) / np.maximum(cnt, 1)[:, None]
    uf, _ = tracks_of(fpc, links.subset(before))
    ids = uf[np.minimum(gid.min(1), max(int(off[-1]) - 1, 0))] if T else np.zeros(0, np.int64)
    fusion_heads = [h["fusion"] for h in heads.values() if h.get("fusion")]
    mode = fusion_heads[0].get("consensus", "metropolis") if fusion_heads else None
    # the exact mode floods (no separate max-c rounds); Metropolis: n - 1 max-c rounds first
    maxc = max(n - 1, 0) if mode == "metropolis" else 0
    stats = dict(
        enabled=True, transport="zenoh", consensus=mode, rounds=int(rounds), maxc_rounds=maxc,
        consensus_rounds=max(int(rounds) - maxc, 0),
        settled=(bool(rounds - maxc < 100) if mode == "metropolis"
                 else not any(h.get("forced", False) for h in fusion_heads)),
        messages=int(sum(msgs.values())), bytes=int(sum(byts.values())),
        messages_by_kind={k: v for k, v in msgs.items() if v},
        bytes_by_kind={k: v for k, v in byts.items() if v},
        setup_messages=int(msgs["fusion-setup"]), setup_bytes=int(byts["fusion-setup"]),
        tracks_fused=int(has_pt.sum()),
        observations_estimated=int(sum(h["estimated"] for h in fusion_heads)),
        observations_cut=int(sum(h["outliers"] for h in fusion_heads)),
        links_cut=int(cut.sum()),
        hypotheses=int(fusion_heads[0]["hypotheses"]) if fusion_heads else 0,
        retransmissions=int(sum(h.get("retransmissions", 0) for h in fusion_heads)),
        phase_rounds=max((int(h["rounds"]) for h in fusion_heads), default=0),
        robots_lost={str(i): h["lost"] for i, h in sorted(
            (i, (hh.get("fusion") or {})) for i, hh in heads.items()) if h.get("lost")})
    return stats, pts[has_pt], ids[has_pt]


def run_formation_team(config, timer: StageTimer | None = None, *, kill=None,
                       workdir=None, keep_run: list | None = None,
                       round_timeout_s: float = 5.0):
    """``run-formation --transport zenoh``: one robot process per camera; returns the run path.

    Parameters
    ----------
    config : FormationConfig
    kill : ``(robot, status, delay_s)`` or None — ``kill -9`` a robot mid-run (tests, bench)
    round_timeout_s : float — wait for a neighbour's packet before it counts as silent
    workdir : folder for TEAM.json and the robots' logs (default: temporary)
    keep_run : list or None — the :class:`~pipeline.launcher.TeamRun` is appended to it
    """
    import data_synth
    from pipeline.features import extract
    from pipeline.run import (
        CleaningResult,
        _conflictive_links,
        ledger_from_consistency,
        merge_radius_for,
        write_formation_run,
    )
    from pipeline.types import Features

    timer = timer or StageTimer()
    opts = team_options(config.features, config.max_features, config.faults, round_timeout_s,
                        merge_radius_for(config.resolution, config.merge_radius),
                        config.resolution, fusion=bool(config.fusion))
    edges = data_synth.formation_edges(config.formation, config.seed, config.robots,
                                       config.graph)
    n = config.robots or 6
    data = {"kind": "formation", "formation": config.formation, "seed": int(config.seed),
            "size": [int(v) for v in config.size], "robots": config.robots,
            "graph": config.graph}
    name = f"formation-{config.formation}" if config.robots is None else \
        f"formation-n{config.robots}-{config.graph}"
    team = make_team(name, edges, data, opts, n=n)
    with timer.stage("team", f"{n} robot processes over zenoh"):
        run = launch_team(team, workdir, kill=kill)
        timer.note(f"{len(run.results)} of {n} robots published; "
                   f"process start {run.start_s:.2f} s")
    if keep_run is not None:
        keep_run.append(run)
    with timer.stage("render", "observer: ground truth for the evaluation"):
        formation = data_synth.render(config.formation, seed=config.seed, size=config.size,
                                      n_robots=config.robots, graph=config.graph)
    feats = []
    for i, v in enumerate(formation.views):
        if i in run.results:
            kp = run.results[i][1]["keypoints"].reshape(-1, 2)
            feats.append(Features(kp, np.zeros((len(kp), 0), np.float32),
                                  np.zeros(len(kp), np.float32), config.features))
        else:  # a robot lost before publishing: the evaluation extracts its features itself
            feats.append(extract(v, config.features, config.max_features,
                                 opts["merge_radius"]))
    matches, links = links_of_team(team, run.results)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    res = consistency_of_team(team, run.results, links, m, run.killed)
    cleaning = CleaningResult(ledger_from_consistency(res, _conflictive_links(m, links)),
                              dict(res.stats))
    if config.fusion:
        with timer.stage("fusion", "observer: the links the robots cut in their fusion stage"):
            stats, pts, ids = fusion_of_team(team, run.results, cleaning.ledger, m)
            cleaning.fusion_stats = stats
            cleaning.fused_points, cleaning.fused_track_ids = pts, ids
            timer.note(f"{stats['links_cut']} links cut as fusion outliers")
    else:
        cleaning.fusion_stats = {"enabled": False, "reason": "disabled by option"}
    if run.killed or float(opts.get("drop_prob", 0)) > 0:
        from pipeline.faults import FaultConfig, fault_report

        fc = config.faults or FaultConfig()
        cleaning.faults = fault_report(fc, res)
        cleaning.faults["killed"] = sorted(int(k) for k in run.killed)
    return write_formation_run(config, formation, feats, matches, cleaning, timer,
                               extra={"team": team_summary(run)})


def resolve_conflicts_team(links_csv, fpc, comm_edges, options: dict | None = None, *,
                           kill=None, workdir=None, keep_run: list | None = None
                           ) -> ConsistencyResult:
    """``resolve --transport zenoh``: each robot reads its own rows of ``links_csv``."""
    from pipeline.linkscsv import read_links_csv

    fpc = [int(v) for v in np.asarray(fpc).reshape(-1)]
    edges = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
    data = {"kind": "links", "links": str(Path(links_csv).resolve()),
            "features_per_camera": fpc}
    team = make_team("resolve", edges, data, options, n=len(fpc))
    run = launch_team(team, workdir, kill=kill)
    if keep_run is not None:
        keep_run.append(run)
    links = read_links_csv(links_csv).links
    res = consistency_of_team(team, run.results, links, fpc, run.killed)
    res.stats["team"] = team_summary(run)
    return res



def images_team(config, views, comm_edges, timer: StageTimer | None = None, *, workdir=None,
                keep_run: list | None = None):
    """``run-images --transport zenoh``: one robot process per photograph.

    Each robot loads only its own photograph (downscaled to ``config.max_size``, with the
    intrinsics the observer resolved for it, written into ``TEAM.json``), extracts with the
    run's feature options (the photo defaults unless changed), and matches with its
    comm-graph neighbours; the team then runs detection and resolution (``config.resolution``).

    Returns
    -------
    (features, matches, links, CleaningResult, team section)
        ``features`` hold the keypoints the robots published (descriptors are not sent to the
        observer), in camera order.

    Raises
    ------
    InputError
        A ``knn:K`` graph (it is chosen from every image's features at once: over zenoh give
        a graph kind or file).
    """
    from pipeline.run import (
        CleaningResult,
        _conflictive_links,
        ledger_from_consistency,
        merge_radius_for,
    )
    from pipeline.types import Features

    timer = timer or StageTimer()
    if comm_edges is None:
        raise InputError(f"--graph {config.graph}: knn:K chooses neighbours from every image's "
                         "features at once; with --transport zenoh give ring, ring2, complete, "
                         "seq:K or a graph file")
    directory = Path(config.directory).resolve()
    data = {"kind": "images", "images": [str(directory / v.name) for v in views],
            "intrinsics": [np.asarray(v.K, np.float64).tolist() for v in views],
            "intrinsics_known": [bool(v.intrinsics_known) for v in views],
            "max_size": config.max_size}
    opts = team_options(config.features, config.max_features, None,
                        merge_radius=merge_radius_for(config.resolution, config.merge_radius),
                        resolution=config.resolution,
                        contrast_threshold=config.contrast_threshold,
                        rootsift=bool(config.rootsift),
                        budget_after_merge=bool(config.budget_after_merge),
                        threshold_px=config.threshold_px)
    n = len(views)
    team = make_team(f"images-{n}", comm_edges, data, opts, n=n)
    with timer.stage("team", f"{n} robot processes over zenoh"):
        run = launch_team(team, workdir)
        timer.note(f"{len(run.results)} of {n} robots published; "
                   f"process start {run.start_s:.2f} s")
    if keep_run is not None:
        keep_run.append(run)
    lost = sorted(set(range(n)) - set(run.results))
    if lost:
        raise TeamError(f"robot {lost[0]} ({views[lost[0]].name}) did not publish a result")
    feats = []
    for i in range(n):
        kp = run.results[i][1]["keypoints"].reshape(-1, 2)
        feats.append(Features(kp, np.zeros((len(kp), 0), np.float32),
                              np.zeros(len(kp), np.float32), config.features))
    matches, links = links_of_team(team, run.results)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    res = consistency_of_team(team, run.results, links, m, run.killed)
    cleaning = CleaningResult(ledger_from_consistency(res, _conflictive_links(m, links)),
                              dict(res.stats), fusion_stats=dict(FUSION_SKIPPED))
    return feats, matches, links, cleaning, team_summary(run)
