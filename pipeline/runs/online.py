"""The ``run-formation --steps N`` job: a formation in motion, associated online, step by step.

Each step every robot renders one frame (:func:`data_synth.motion.render_motion`), extracts
its features and matches the new frame against its own ``W - 1`` previous frames and the
last ``W`` frames (this step's included) of every robot it can talk to at this step (an edge
of the step's communication graph), ``W`` = ``window``. The new links go to the online stage
(:class:`pipeline.consistency.engines.online.OnlineAssociation`: detection and the rule on
what they touch, the history check; a frame's links stay open ``hold`` steps after it leaves
the matching window, default ``W - 1``); the kept association is checked conflict-free after
every step (a centralized count, evaluation only). Optionally (``batch_every``) the same
rule is run from scratch on all links so far (the batch run) for comparison.

Fusion (``fusion``, default on): after each step the tracks the step changed (the sets its
stage ran on, window frames only) are fused again by robust distributed fusion
(Montijano et al., dynamic voting, :func:`pipeline.fusion.landmarks.fuse_tracks`, frames as
its robots, frames sharing a link as neighbours), as the ``online_fusion`` job of the run's
transport (in this process, or one robot process per frame over Zenoh); each track named by
the smallest global feature id of its set, as the robots name it when they detect their sets
(the name seeds their max-c draws); a link with exactly one end voted out is cut as
``fusion-outlier`` (an outlier leaves its landmark, a link between two outliers stays where
they can be one point:
:mod:`pipeline.fusion.landmarks`; a cut only splits a set: the association stays
conflict-free). Tracks no
link of the step touched keep their last fusion. The step record carries ``fusion`` (rounds,
bytes, links cut, tracks fused, wall time), apart from the consistency stage's figures.

Robot processes lost (``--transport zenoh``): a team of a step's matching, stage or fusion
that loses a robot is started again (the matching's ``match_attempts``,
``match_robots_lost``); a frame lost twice in a step's stage or fusion is given up for it
(its links of the step's stage cut ``robot-lost``, :meth:`pipeline.consistency.engines.
online.OnlineAssociation._stage_despite_losses`; left out of the step's fusion,
:func:`_fuse_changed`). A robot lost again by its step's matching team started again does
not stop the run: its new frame is *void* (no features: ``match_frames_void``; a robot
lost for good has every later frame void too) and the step's pairs no robot could match
have no links (``match_pairs_unmatched``): :func:`pipeline.runs.transports.zenoh.
online_match`.

Outputs (run folder, written atomically): ``report.json`` (``steps``: one entry per step
with ``links_new``, ``conflictive_sets_after``, ``wall_s``, ``rounds``, ``bytes`` and the
rest of the online record, and the batch run's figures where it ran; ``final``: pairwise
scores of the online and batch associations on the scope of
:mod:`pipeline.evaluation.online`), ``links.csv`` (cameras are frames; ``round`` is the step
that cut the link), ``images.csv`` (frame -> robot, step, name), ``link_steps.csv`` (step
that made and step that cut each link) and ``recording.rrd`` (a ``step`` timeline:
:mod:`viz.online_log`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from data_synth.motion import DEFAULT_SPEED
from pipeline.consistency.rules import DEFAULT_RESOLUTION
from pipeline.progress import StageTimer, counted
from pipeline.types import Links

__all__ = ["OnlineConfig", "OnlineRun", "run_online_steps", "run_online",
           "track_names",
           "associate_online", "batch_steps_of", "online_tables", "jsonable_step"]


@dataclass
class OnlineConfig:
    """Options of ``run-formation --steps N``."""

    formation: str = "d"
    seed: int = 0
    size: tuple[int, int] = (320, 240)
    features: str = "sift"
    max_features: int = 500
    robots: int | None = None
    graph: str | None = None
    steps: int = 10
    window: int = 3
    speed: float = DEFAULT_SPEED
    switching: bool = False
    resolution: str = DEFAULT_RESOLUTION
    tol_px: float = 2.0
    batch_every: int = 0
    fusion: bool = True
    out: str | None = None
    rerun: bool = True
    #: the history repair may overturn open links (OnlineAssociation, step 3)
    overturn: bool = True
    #: steps a frame's links stay open after it leaves the matching window (OnlineAssociation,
    #: *Hold*; None: ``window - 1``)
    hold: int | None = None
    #: the sets the detection finds conflict-free are weighed by the rule's merge too
    #: (OnlineAssociation, step 2b; the evidence rule)
    weigh: bool = True
    #: the rule's small conflictive sets are solved at their roots (bundles gathered), not by
    #: the rule's flood to every robot of the set: the same cuts, fewer bytes
    gather: bool = True
    #: the simulator's robots run the roots' protocol themselves, each on its own inbox
    #: (OnlineAssociation ``robots_solve``; a transport of processes always does), instead
    #: of its batched solution: the same cuts, the protocol's own rounds and bytes
    robots_solve: bool = False
    #: the stage's robots run the history check (OnlineAssociation ``robots_check``, step 3;
    #: default): False, the record's own check, the same cuts, its cost an estimate
    robots_check: bool = True
    #: where the robots run the rule's stage of each step (:mod:`pipeline.runs.transports`)
    transport: str = "sim"
    #: keypoints of one frame closer than this are one feature (None: the co-location radius,
    #: :data:`pipeline.matching.features.MERGE_RADIUS_PX`, whatever the rule)
    merge_radius: float | None = None

    def out_dir(self) -> Path:
        if self.out:
            return Path(self.out)
        name = f"online-{self.formation}" if self.robots is None else \
            f"online-n{self.robots}-{self.graph}"
        return Path("runs") / name


@dataclass
class OnlineRun:
    """What :func:`run_online_steps` produced: the sequence, every frame's features, the
    online association, per-step records (online and batch), the last batch result and,
    once evaluated, each link's truth (``1`` good, ``0`` spurious); ``batch_kept``: step ->
    the batch run's kept mask over the links made up to that step."""

    sequence: object
    features: list
    online: object
    steps: list
    batch: object | None
    truth: np.ndarray | None = None
    batch_kept: dict | None = None

    def online_kept_at(self, step: int) -> np.ndarray:
        """The online association's kept mask over the links made up to ``step``, as it
        stood after that step."""
        L = self.online.links
        upto = L.step_added <= step
        return (L.kept | (L.step_cut > step))[upto]


def track_names(features_per_camera, links: Links) -> np.ndarray:
    """Each feature's track named as robots that detect their association sets name it: the
    smallest global feature id of its set (Prop. 3.5; :meth:`pipeline.consistency.robot.Robot.
    final_tracks`), ``-1`` outside tracks.

    Examples
    --------
    >>> L = Links(np.array([0, 1]), np.array([1, 0]), np.array([1, 2]), np.array([0, 1]))
    >>> track_names([2, 1, 2], L).tolist()
    [-1, 1, 1, -1, 1]
    """
    from pipeline.fusion.landmarks import tracks_of

    track_of, T = tracks_of(np.asarray(features_per_camera, np.int64), links)
    inside = np.flatnonzero(track_of >= 0)
    smallest = np.full(T, np.iinfo(np.int64).max, np.int64)
    np.minimum.at(smallest, track_of[inside], inside)
    names = np.full(len(track_of), -1, np.int64)
    names[inside] = smallest[track_of[inside]]
    return names


def _fuse_changed(oa, views: list, features: list, fuse) -> dict:
    """Fusion of the tracks the last step changed (module docstring) by ``fuse``, the run's
    transport's ``online_fusion`` job (:mod:`pipeline.runs.transports`), with the tracks named
    by :func:`track_names`; returns its figures (over zenoh also the rounds and bytes the
    robots spent naming their tracks, ``naming_rounds`` and ``naming_bytes``).

    A fusion team that loses a robot (:class:`~pipeline.errors.RobotsLost`) is started again;
    a frame lost a second time in the step is left out of the step's fusion (its links are
    not handed to it, so none of them is cut as ``fusion-outlier`` and it votes in no
    decision, as a robot crashed during a batch run's fusion). ``frames_lost`` lists, per
    lost attempt, the frames it lost; ``frames_left_out`` those left out."""
    from pipeline.errors import RobotsLost

    t0 = time.perf_counter()
    ids = oa.changed_window_links()
    L = oa.links
    if not len(ids):
        return dict(rounds=0, messages=0, bytes=0, cut=0, tracks=0, wall_s=0.0)
    lost_log: list[list[int]] = []
    seen: set = set()
    out_frames: list[int] = []
    while True:
        if out_frames:
            ids = ids[~(np.isin(L.ci[ids], out_frames) | np.isin(L.cj[ids], out_frames))]
        if not len(ids):
            fr = None
            break
        images = np.unique(np.concatenate([L.ci[ids], L.cj[ids]]))
        ci, cj = np.searchsorted(images, L.ci[ids]), np.searchsorted(images, L.cj[ids])
        local = Links(ci, L.fi[ids], cj, L.fj[ids], L.quality[ids])
        edges = np.unique(np.stack([ci, cj], axis=1), axis=0)
        feats = [features[g] for g in images]
        try:
            fr = fuse([views[g] for g in images], feats, local, edges,
                      track_labels=track_names([len(f) for f in feats], local))
            break
        except RobotsLost as e:
            lost = [int(images[c]) for c in e.cameras]
            lost_log.append(lost)
            out_frames += [g for g in lost if g in seen]
            seen.update(lost)
    out = dict(rounds=0, messages=0, bytes=0, cut=0, tracks=0)
    if fr is not None:
        cut = ids[np.asarray(fr.cut_links, bool)]
        oa.cut(cut, "fusion-outlier")
        st = fr.stats
        out = dict(rounds=int(st.get("rounds", 0)), messages=int(st.get("messages", 0)),
                   bytes=int(st.get("bytes", 0)), cut=int(len(cut)),
                   tracks=int(len(fr.track_ids)))
        out.update({k: int(st[k]) for k in ("naming_rounds", "naming_bytes") if k in st})
    if lost_log:
        out.update(frames_lost=lost_log, frames_left_out=sorted(out_frames))
    out["wall_s"] = time.perf_counter() - t0
    return out


def _memory(features: list, desc_bytes: list, images: np.ndarray, robot_of: np.ndarray, n: int,
            keypoints_only: np.ndarray | None = None) -> np.ndarray:
    """Bytes of keypoints and descriptors (``desc_bytes`` per frame) each robot holds for
    ``images``, and of keypoints only for ``keypoints_only`` (held frames: no new match, so no
    descriptors)."""
    out = np.zeros(n, np.int64)
    for g in images.tolist():
        out[robot_of[g]] += features[g].keypoints.nbytes + desc_bytes[g]
    for g in (() if keypoints_only is None else keypoints_only.tolist()):
        out[robot_of[g]] += features[g].keypoints.nbytes
    return out


def run_online_steps(config: OnlineConfig, timer: StageTimer | None = None,
                     batch_steps=None, on_step=None) -> OnlineRun:
    """Render, match and associate online step by step (module docstring).

    ``batch_steps``: the steps at which the batch run goes (default every
    ``config.batch_every`` steps and the last, none with ``batch_every == 0``). ``on_step``:
    called with each step's record. Returns an :class:`OnlineRun`.
    """
    from data_synth.motion import render_motion

    timer = timer or StageTimer(verbose=False)
    with timer.stage("render", counted(config.steps, "step")):
        seq = render_motion(config.formation, config.seed, config.steps, config.size,
                            config.robots, config.graph, speed=config.speed,
                            switching=config.switching, window=config.window)
    if batch_steps is None:
        batch_steps = batch_steps_of(config.steps, config.batch_every)
    run = associate_online(seq.flat.views, seq.n_robots, seq.step_edges, config.window,
                           config.resolution, timer, features=config.features,
                           max_features=config.max_features, fusion=config.fusion,
                           batch_steps=batch_steps, on_step=on_step, overturn=config.overturn,
                           hold=config.hold, weigh=config.weigh, gather=config.gather,
                           transport=config.transport, robots_solve=config.robots_solve,
                           robots_check=config.robots_check,
                           feature_options={"merge_radius": config.merge_radius})
    run.sequence = seq
    return run


def batch_steps_of(steps: int, every: int) -> set:
    """The steps of the batch run: every ``every`` steps and the last (none if ``every`` is
    0)."""
    every = int(every)
    return set() if every <= 0 else \
        {t for t in range(steps) if (t + 1) % every == 0} | {steps - 1}


def associate_online(views: list, n: int, step_edges: list, window: int, resolution: str,
                     timer: StageTimer, *, features: str = "sift",
                     max_features: int | None = 500, fusion: bool = True,
                     batch_steps=frozenset(), on_step=None, feature_options=None,
                     match_options=None, overturn: bool = True,
                     hold: int | None = None, weigh: bool = True,
                     gather: bool = True, transport: str = "sim",
                     robots_solve: bool = False, robots_check: bool = True) -> OnlineRun:
    """The online loop on frames already at hand: ``views[k * n + i]`` is robot ``i``'s frame
    of step ``k``, ``step_edges[k]`` the robots that talk at step ``k``. Each step: features
    of the new frames, matching on :func:`pipeline.matching.pairs.step_pairs`, the online
    stage, fusion of the changed tracks (needs poses), the batch run at ``batch_steps``. ``feature_options`` and
    ``match_options`` go to :func:`pipeline.matching.features.extract_all` and
    :func:`pipeline.matching.pairs.match_edges`; ``overturn``, ``hold``, ``weigh``, ``gather``, ``robots_solve`` and ``robots_check`` to the online stage; ``transport``
    names where the robots match, run the rule's stage and fuse at each step (its
    ``online_robots``, ``online_match``, ``online_stage`` and ``online_fusion`` jobs; the
    batch run stays on the simulator). Returns an :class:`OnlineRun` without ``sequence``."""
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.consistency.engines.online import Frame, OnlineAssociation, batch_resolve
    from pipeline.matching.features import MERGE_RADIUS_PX
    from pipeline.runs.transports import get_transport

    feature_options = dict(feature_options or {})
    match_options = dict(match_options or {})
    radius = feature_options.pop("merge_radius", None)
    radius = MERGE_RADIUS_PX if radius is None else radius
    steps = len(step_edges)
    jobs = get_transport(transport).load()
    stage = jobs.online_stage
    # robot processes solve the sets at their roots themselves; the simulator solves them in
    # batch (the same protocol's decisions, property-tested)
    oa = OnlineAssociation(window, resolution=resolution, overturn=overturn, hold=hold,
                           weigh=weigh, gather=gather, stage=stage,
                           robots_solve=robots_solve
                           or bool(getattr(jobs, "ONLINE_ROBOTS_SOLVE", False)),
                           robots_check=robots_check
                           or bool(getattr(jobs, "ONLINE_ROBOTS_SOLVE", False)))
    feats_all: list = []
    robot_of = np.zeros(0, np.int64)
    step_of = np.zeros(0, np.int64)
    records, batch, batch_kept = [], None, {}
    desc_bytes: list = []  # bytes of each frame's descriptors (held by its robot)
    with jobs.online_robots() as store, timer.stage("online", f"{counted(steps, 'step')}, window {window}"):
        for t in range(steps):
            ids = [t * n + i for i in range(n)]
            t0 = time.perf_counter()
            robot_of = np.concatenate([robot_of, np.arange(n)])
            step_of = np.concatenate([step_of, np.full(n, t)])
            # the robots' own matching (over Zenoh each robot process matches its pairs,
            # keeping its window's features in its own folder: pipeline.team.online_match)
            feats, links, stats = jobs.online_match(
                views, t, n, window, step_edges[t], store, features=features,
                max_features=max_features, merge_radius=radius,
                feature_options=feature_options, match_options=match_options)
            feats_all += feats
            desc_bytes += stats["descriptor_bytes"]
            match_rec = {f"match_{k}": stats[k] for k in ("messages", "bytes", "held_bytes_max",
                                                          "attempts", "robots_lost",
                                                          "frames_void", "pairs_unmatched")
                         if k in stats}
            match_s = time.perf_counter() - t0
            frames = [Frame(i, len(f), f.keypoints, None if views[g].R is None else
                            views[g].K @ np.c_[views[g].R, views[g].t])
                      for i, (g, f) in enumerate(zip(ids, feats, strict=True))]
            rec = dict(oa.add_step(frames, links))
            if fusion:
                rec["fusion"] = _fuse_changed(oa, views, feats_all, jobs.online_fusion)
            kept = oa.kept_links()
            counts = count_conflicts(AssociationGraph(oa.m, kept))
            rec.update(match_s=match_s, pairs_matched=int(stats["pairs"]), **match_rec,
                       comm_edges=np.asarray(step_edges[t], np.int64).reshape(-1, 2).tolist(),
                       conflictive_sets_after=int(counts.conflictive_sets),
                       links_total=int(len(oa.links.ci)), links_kept=int(len(kept)))
            w = oa.window_images
            matching = step_of[w] > t - window  # held frames keep their keypoints only
            desc = _memory(feats_all, desc_bytes, w[matching], robot_of, n,
                           keypoints_only=w[~matching])
            rec["robot_memory_bytes_max"] = int((desc + oa.robot_state_bytes()).max())
            if t in batch_steps:
                t1 = time.perf_counter()
                batch = batch_resolve(oa.m, oa.all_links(), resolution,
                                      keypoints=oa.keypoints, projections=oa.projection
                                      if all(p is not None for p in oa.projection) else None)
                bs = batch.stats
                all_img = np.arange(len(feats_all))
                b_state = _memory(feats_all, desc_bytes, all_img, robot_of, n)
                np.add.at(b_state, robot_of, 16 * oa.m)
                np.add.at(b_state, robot_of[oa.links.ci], 40)
                np.add.at(b_state, robot_of[oa.links.cj], 40)
                kept_b = batch.links.subset(~batch.deleted)
                batch_kept[t] = ~batch.deleted
                rec["batch"] = dict(
                    wall_s=time.perf_counter() - t1,
                    rounds=int(bs["detection_rounds"] + bs["resolution_rounds"]),
                    messages=int(bs["messages"]), bytes=int(bs["bytes"]),
                    stage_peak_bytes=int(bs["max_robot_memory_bytes"]),
                    robot_memory_bytes_max=int(b_state.max()),
                    cut=int(batch.deleted.sum()),
                    conflictive_sets_after=int(count_conflicts(
                        AssociationGraph(oa.m, kept_b)).conflictive_sets))
            records.append(rec)
            if on_step is not None:
                on_step(rec)
            # the fusion's cuts are links cut at this step too (links.csv, link_steps.csv)
            by_fusion = f", {rec['fusion']['cut']} cut by fusion" if fusion else ""
            lost = sorted({g for att in rec["images_lost"] for g in att}
                          | {g for att in rec.get("fusion", {}).get("frames_lost", ())
                             for g in att}
                          | {t * n + i for att in rec.get("match_robots_lost", ())
                             for i in att})
            if lost:  # robot processes lost and started again (or given up for the step)
                by_fusion += (f", robot processes of frame(s) {', '.join(map(str, lost))} "
                              f"lost and started again ({rec['cut_lost']} links cut "
                              "robot-lost")
                out = rec.get("fusion", {}).get("frames_left_out", [])
                by_fusion += (f"; frame(s) {', '.join(map(str, out))} left out of the "
                              "step's fusion, lost twice)" if out else ")")
            if rec.get("match_frames_void"):
                by_fusion += (f", frame(s) {', '.join(map(str, rec['match_frames_void']))} "
                              "void (their robots lost twice by the matching: no features; "
                              f"{rec['match_pairs_unmatched']} frame pairs not matched)")
            timer.note(f"step {t}: {rec['links_new']} new links, {rec['cut']} cut{by_fusion}, "
                       f"{rec['conflictive_sets_after']} conflictive sets after, "
                       f"{rec['rounds']} rounds, {rec['bytes']} bytes, "
                       f"{rec['wall_s']:.3f} s")
    return OnlineRun(sequence=None, features=feats_all, online=oa, steps=records, batch=batch,
                     batch_kept=batch_kept)


def run_online(config: OnlineConfig, timer: StageTimer | None = None) -> Path:
    """Run :func:`run_online_steps` (with the batch run at the last step), evaluate against
    the ground truth and write the run folder (module docstring); return its path."""
    timer = timer or StageTimer()
    run = run_online_steps(config, timer, batch_steps={config.steps - 1}
                           if config.batch_every == 0 else None)
    report = online_report(config, run, timer)
    online_tables(config.out_dir(), run, report, timer,
                  [v.name for v in run.sequence.flat.views], rerun=config.rerun)
    return config.out_dir()


def online_report(config: OnlineConfig, run: OnlineRun, timer: StageTimer) -> dict:
    """``report.json`` of an online run: config, steps, and the final scores."""
    from data_synth import formation_name, formation_used
    from pipeline.evaluation.links import link_truth
    from pipeline.evaluation.online import ScopedTruth, scope_pairs
    from pipeline.evaluation.report import versions
    from pipeline.matching.features import MERGE_RADIUS_PX

    oa, seq = run.online, run.sequence
    links = oa.all_links()
    with timer.stage("evaluate", f"ground truth at {config.tol_px} px"):
        truth = np.asarray(link_truth(seq.flat, run.features, links, tol_px=config.tol_px),
                           bool)
        scope = scope_pairs(oa.robot, oa.step, seq.comm_edges, config.window,
                            step_edges=seq.step_edges)
        st = ScopedTruth(seq.flat, run.features, scope, tol_px=config.tol_px)
        final = {"links": int(len(links)), "good_links": int(truth.sum()),
                 "scope_image_pairs": int(len(scope)),
                 "before": st.scores(links)}
        kept = oa.links.kept
        if config.fusion:  # the consistency stage's own result: fusion's cuts put back
            resolved = kept | (oa.links.reason == "fusion-outlier")
            final["online_before_fusion"] = dict(st.scores(links.subset(resolved)),
                                                 kept=int(resolved.sum()))
        final["online"] = dict(st.scores(links.subset(kept)), kept=int(kept.sum()),
                               good_kept=int((truth & kept).sum()),
                               conflictive_sets=int(run.steps[-1]["conflictive_sets_after"]),
                               cut_by_reason={str(r): int((oa.links.reason == r).sum())
                                              for r in sorted(set(oa.links.reason[~kept]))})
        if run.batch is not None and len(run.batch.deleted) == len(links):
            # the batch run of the last step (an earlier one is scored by the caller, on the
            # links of its own step: OnlineRun.batch_kept and online_kept_at)
            kb = ~run.batch.deleted
            final["batch"] = dict(st.scores(links.subset(kb)), kept=int(kb.sum()),
                                  good_kept=int((truth & kb).sum()),
                                  conflictive_sets=int(run.steps[-1]["batch"]
                                                       ["conflictive_sets_after"]))
    run.truth = truth.astype(np.int8)
    report = {
        "title": formation_name(config.formation, config.robots, config.graph)
                 + f" in motion ({counted(config.steps, 'step')}, seed "
                 f"{config.seed})",
        "n_robots": int(seq.n_robots),
        "n_images": int(oa.n_images),
        "comm_edges": np.asarray(seq.comm_edges).tolist(),
        "features_per_camera": [int(len(f)) for f in run.features],
        "window": int(config.window),
        "hold": int(oa.hold),
        "resolution": oa.resolution,
        "steps": [jsonable_step(r) for r in run.steps],
        "final": final,
        "conflict_free_every_step": bool(all(r["conflictive_sets_after"] == 0
                                             for r in run.steps)),
        "fusion": {"enabled": bool(config.fusion),
                   "scope": "the tracks each step changed, window frames only",
                   "links_cut": int((oa.links.reason == "fusion-outlier").sum())},
        "ground_truth": {"tolerance_px": config.tol_px},
        "versions": versions(),
        "config": {**asdict(config), "formation": formation_used(config.formation, config.graph),
                   # the radius the keypoints were merged at (merge_radius null: the online
                   # run's own, MERGE_RADIUS_PX, whatever the rule)
                   "merge_radius_used_px": float(MERGE_RADIUS_PX if config.merge_radius is None
                                                 else config.merge_radius),
                   "out": str(config.out_dir())},
    }
    from pipeline.outcome import flag_online, merge_radius_why

    if config.switching and not any(len(s.get("comm_edges", ())) for s in report["steps"]):
        # no frame had a neighbour to match: the drawn graphs, not the images, are the cause
        why = (f"--switching-topology left no communication link up in any of the "
               f"{len(run.steps)} step(s) (drawn from --seed); more --steps, or another --seed")
    else:
        # the robots of one step see the scene alike whatever the speed: it can leave them
        # without a link only by driving them beside the scene, where a frame sees only sky
        left = config.speed and 0 in report["features_per_camera"]
        why = ("frames too small, too few features, or no overlap between the robots' views"
               + merge_radius_why(config.merge_radius, config.size)
               + (f"; at --speed {config.speed:g} m per step the formation may have left the "
                  "scene" if left else ""))
    return flag_online(report, why, [v.name for v in seq.flat.views])


def jsonable_step(rec: dict) -> dict:
    """A step record as ``report.json`` holds it (plain numbers, floats rounded)."""
    out = {}
    for k, v in rec.items():
        if isinstance(v, dict):
            out[k] = jsonable_step(v)
        elif isinstance(v, (np.integer,)):
            out[k] = int(v)
        elif isinstance(v, (float, np.floating)):
            out[k] = round(float(v), 6)
        else:
            out[k] = v
    return out


def _write_images_csv(path: Path, oa, names: list) -> None:
    """``images.csv``: frame, robot, step, name; a name holding a comma, a quote or a line
    break (file and folder names may) is quoted as CSV does, so each frame stays one row."""
    import csv

    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["image", "robot", "step", "name"])
        w.writerows([g, int(oa.robot[g]), int(oa.step[g]), names[g]] for g in range(oa.n_images))


def online_tables(out: Path, run: OnlineRun, report: dict, timer: StageTimer, names: list,
                  rerun: bool = True, centres: np.ndarray | None = None) -> None:
    """Write the run folder of an online run atomically: ``links.csv``, ``images.csv``
    (``names``: each frame's name), ``link_steps.csv``, ``report.json`` and, with ``rerun``,
    ``recording.rrd`` (robots at their frames' centres, or at ``centres``)."""
    from pipeline.inputs.linkscsv import write_links_csv
    from pipeline.runfolder import atomic_run_folder, write_json_atomic
    from pipeline.types import LinkLedger

    oa = run.online
    L = oa.links
    ledger = LinkLedger(oa.all_links(), np.where(L.kept, "kept", "deleted").astype(object),
                        L.reason.astype(object), np.where(L.kept, -1, L.step_cut),
                        np.full(len(L.ci), -1, np.int64),
                        np.full(len(L.ci), "", dtype=object),
                        truth=run.truth)
    with timer.stage("write", str(out)):
        with atomic_run_folder(out) as tmp:
            write_links_csv(tmp / "links.csv", ledger)
            _write_images_csv(tmp / "images.csv", oa, names)
            rows = ["link,step_added,step_cut"] + [
                f"{k},{int(a)},{'' if c < 0 else int(c)}"
                for k, (a, c) in enumerate(zip(L.step_added, L.step_cut, strict=True))]
            (tmp / "link_steps.csv").write_text("\n".join(rows) + "\n")
            if rerun:
                from viz.online_log import log_online

                log_online(tmp / "recording.rrd", run.sequence, oa, report["steps"],
                           centres=centres)
            report["timings_s"] = {k: round(v, 4) for k, v in timer.timings.items()}
            write_json_atomic(tmp / "report.json", report)
