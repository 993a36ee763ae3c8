"""The ``zenoh`` transport: one process per robot, talking over Zenoh (:mod:`pipeline.team`).

The robots compute everything (:mod:`pipeline.team.robot`); this process launches them
(:mod:`pipeline.team.launcher`) and, as the observer, turns what they published into the
job's results (:mod:`pipeline.team.assemble`). The job functions are those of the registry
(:mod:`pipeline.runs.transports`); ``team_time_limit`` (the launcher's) bounds every team they
start (``--team-timeout``), and ``team_round_timeout`` (the launcher's) sets the silence after
which its robots write a neighbour off (``--round-timeout``). Every team runs on this
machine's loopback, or each robot on a host of its own (a network namespace, one cable per
comm edge) as :data:`HOSTS_ENV` says (:func:`team_launcher`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import json
from pathlib import Path

import numpy as np

from pipeline.association import conflictive_links
from pipeline.consistency.result import ConsistencyResult
from pipeline.errors import InputError, RobotsLost, TeamError, listed, processes_lost
from pipeline.faults import FaultConfig
from pipeline.progress import StageTimer
from pipeline.runs.transports.results import FormationRobots, ImagesRobots
from pipeline.stages import (
    CleaningResult,
    ledger_from_consistency,
    merge_radius_for,
    photo_merge_radius,
)
from pipeline.team.assemble import (
    FUSION_SKIPPED,
    consistency_of_team,
    fusion_of_team,
    links_of_team,
    team_options,
)
from pipeline.team.launcher import (
    TEAM_TIMEOUT_S,
    launch_team,
    lost_robots,
    make_team,
    shared_zygote,
    team_round_timeout,
    team_summary,
    team_time_limit,
)

__all__ = ["formation", "formation_of_run", "images", "images_of_run", "images_team", "resolve",
           "online_stage", "online_fusion", "job_teams", "online_robots", "ZYGOTE_ENV",
           "HOSTS_ENV", "team_launcher",
           "resolve_links_file", "links_quality_published",
           "write_robot_links", "links_of_run", "team_time_limit", "team_round_timeout",
           "TEAM_TIMEOUT_S"]


#: the robots of an online step solve the small sets at their roots themselves (processes:
#: no one else holds their bundles)
ONLINE_ROBOTS_SOLVE = True

#: the most robot processes a job starts on this machine (each holds an interpreter and a
#: Zenoh session: a links file naming thousands of cameras would otherwise fork thousands of
#: processes); beyond it the job is refused before any work
#: (:func:`pipeline.runs.transports.check_team_size`)
MAX_ROBOT_PROCESSES = 256

#: robots are the cameras that appear in a link or a comm edge (ids made compact,
#: :mod:`pipeline.inputs.compact`): a camera id with nothing to say starts no process
COMPACT_IDS = True


def _robot_rows(links, n: int):
    """``(i, rows)`` for each robot ``i < n``: the rows of ``links`` that touch it, in order
    (the rows of its links file)."""
    for i in range(n):
        yield i, np.flatnonzero((links.cam_i == i) | (links.cam_j == i))


def write_robot_links(folder: Path, links, n: int) -> list[Path]:
    """One links file per robot in ``folder`` (``links-robotI.csv``): the rows of ``links``
    that touch robot ``I``, in their order, with their quality. Returns the paths."""
    paths = []
    for i, sel in _robot_rows(links, n):
        p = folder / f"links-robot{i}.csv"
        p.write_text("cam_i,feat_i,cam_j,feat_j,quality\n" + "".join(
            f"{a},{b},{c},{d},{float(q)!r}\n" for a, b, c, d, q in zip(
                links.cam_i[sel].tolist(), links.feat_i[sel].tolist(),
                links.cam_j[sel].tolist(), links.feat_j[sel].tolist(),
                links.quality[sel].tolist(), strict=True)))
        paths.append(p)
    return paths


def write_robot_weights(folder: Path, links, weights, n: int) -> list[str]:
    """One weights file per robot in ``folder`` (``weights-robotI.csv``, the team file's
    ``data.weights``): header ``weight``, then the weight of each row of its links file
    (:func:`write_robot_links`, the same order), as the shortest text that reads back to the
    same float64. Returns the paths."""
    w = np.asarray(weights, np.float64).reshape(-1)
    paths = []
    for i, sel in _robot_rows(links, n):
        paths.append(str(folder / f"weights-robot{i}.csv"))
        Path(paths[-1]).write_text("weight\n" + "".join(f"{v!r}\n" for v in w[sel].tolist()))
    return paths


def _write_robot_keypoints(folder: Path, keypoints) -> list[str]:
    """One keypoints file per robot in ``folder`` (``keypoints-robotI.csv``, the team file's
    ``data.keypoints``, :func:`pipeline.team.robot.write_keypoints`). Returns the paths."""
    from pipeline.team.robot import write_keypoints

    paths = []
    for i, kp in enumerate(keypoints):
        paths.append(str(folder / f"keypoints-robot{i}.csv"))
        write_keypoints(paths[-1], kp)
    return paths


def _write_robot_history(folder: Path, history, used: np.ndarray, where: np.ndarray
                         ) -> list[str]:
    """One history file per robot process (``history-robotI.npz``, the team file's
    ``data.history``): the inputs of frame ``used[i]``, its rows' neighbours renumbered as
    the processes are (``where``). Returns the paths."""
    from dataclasses import replace

    paths = []
    for i, g in enumerate(np.asarray(used).tolist()):
        inp = history[g]
        inp = replace(inp, row_nbr=np.asarray(where, np.int64)[np.asarray(inp.row_nbr,
                                                                        np.int64)])
        paths.append(str(folder / f"history-robot{i}.npz"))
        np.savez(paths[-1], **inp.to_arrays())
    return paths


def _union_links(parts):
    """The links of per-robot files, each link once, sorted by ``(cam_i, feat_i, cam_j,
    feat_j)``."""
    from pipeline.types import Links

    cat = [np.concatenate([getattr(p, a) for p in parts]) if parts else np.zeros(0, np.int64)
           for a in ("cam_i", "feat_i", "cam_j", "feat_j")]
    q = np.concatenate([p.quality for p in parts]) if parts else np.zeros(0)
    _, first = np.unique(np.stack(cat, 1), axis=0, return_index=True)
    return Links(*(c[first] for c in cat), q[first])


def formation(config, timer: StageTimer, *, kill=None, workdir=None, keep_run: list | None = None,
              round_timeout_s: float | None = None,
              wire: str = "compact", shared_memory: bool = False) -> FormationRobots:
    """``run-formation --transport zenoh``: one robot process per camera.

    The robots render their own cameras, extract, match, resolve and fuse; this process (the
    observer) renders the formation once more for the evaluation only.

    Parameters
    ----------
    config : FormationConfig
    kill : ``(robot, status, delay_s)`` or None — ``kill -9`` a robot mid-run (tests, bench)
    round_timeout_s : float or None — silence after which a neighbour is written off (None:
        the command's ``--round-timeout``, :func:`~pipeline.team.launcher.team_round_timeout`,
        else the team file's default)
    wire : the robots' encoding, ``compact`` or ``plain``
        (:data:`pipeline.team.teamfile.WIRE_FORMS`)
    shared_memory : the team option (Zenoh's shared memory between the robot processes,
        :func:`pipeline.transport.zenoh_transport.zenoh_config`; ``bench/team_memory.py``
        compares the two)
    workdir : folder for TEAM.json and the robots' logs (default: temporary)
    keep_run : list or None — the :class:`~pipeline.team.launcher.TeamRun` is appended to it
    """
    import data_synth

    opts = team_options(config.features, config.max_features, config.faults, round_timeout_s,
                        merge_radius_for(config.resolution, config.merge_radius),
                        config.resolution, fusion=bool(config.fusion), wire=wire,
                        shared_memory=bool(shared_memory))
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
        run = _launch_team(team, workdir, kill=kill)
        timer.note(f"{len(run.results)} of {n} robots published; "
                   f"process start {run.start_s:.2f} s")
    if keep_run is not None:
        keep_run.append(run)
    return formation_of_run(config, team, run, timer)


def formation_of_run(config, team, run, timer: StageTimer) -> FormationRobots:
    """What the robots of ``team`` published in ``run`` (launched here, or observed by
    :mod:`pipeline.team.observe`), as the ``formation`` job's result: the observer renders
    the formation once more for the evaluation only."""
    import data_synth
    from pipeline.matching.features import extract
    from pipeline.types import Features

    opts = team.options
    with timer.stage("render", "observer: ground truth for the evaluation"):
        formation = data_synth.render(config.formation, seed=config.seed, size=config.size,
                                      n_robots=config.robots, graph=config.graph)
    # the graph the robots talked over is the team's (a team file may give other comm_edges
    # than its formation's graph): the evaluation, its missing links, follows it
    formation = dataclasses.replace(
        formation, comm_edges=np.asarray(team.comm_edges, np.int64).reshape(-1, 2))
    feats = []
    for i, v in enumerate(formation.views):
        if i in run.results:
            kp = run.results[i][1]["keypoints"].reshape(-1, 2)
            feats.append(Features(kp, np.zeros((len(kp), 0), np.float32),
                                  np.zeros(len(kp), np.float32), config.features))
        else:  # a robot lost before publishing: the evaluation extracts its features itself
            feats.append(extract(v, config.features, config.max_features or 2000,
                                 merge_radius_for(config.resolution, opts["merge_radius"])))
    matches, links = links_of_team(team, run.results)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    res = consistency_of_team(team, run.results, links, m, run.killed)
    cleaning = CleaningResult(ledger_from_consistency(res, conflictive_links(m, links)),
                              dict(res.stats))
    if config.fusion:
        with timer.stage("fusion", "observer: the links the robots cut in their fusion stage"):
            stats, pts, ids, groups = fusion_of_team(team, run.results, cleaning.ledger, m)
            cleaning.fusion_stats = stats
            cleaning.fused_points, cleaning.fused_track_ids = pts, ids
            cleaning.fused_track_features = groups
            timer.note(f"{stats['links_cut']} links cut as fusion outliers")
    else:
        cleaning.fusion_stats = {"enabled": False, "reason": "disabled by option"}
    if run.killed or len(run.results) < team.n or float(opts.get("drop_prob", 0)) > 0:
        from pipeline.faults import FaultConfig, fault_report

        fc = config.faults or FaultConfig()
        cleaning.faults = fault_report(fc, res)
        cleaning.faults["killed"] = sorted(int(k) for k in run.killed)
    return FormationRobots(formation, feats, matches, cleaning, {"team": team_summary(run)})


def images(config, views, comm_edges, timer: StageTimer, graph_from_features=None, *,
           workdir=None, keep_run: list | None = None) -> ImagesRobots:
    """``run-images --transport zenoh``: one robot process per photograph.

    Each robot loads only its own photograph (downscaled to ``config.max_size``, with the
    intrinsics the observer resolved for it, written into ``TEAM.json``), extracts with the
    run's feature options (the photo defaults unless changed), and matches with its
    comm-graph neighbours; the team then runs detection and resolution (``config.resolution``).

    Returns
    -------
    ImagesRobots
        ``features`` hold the keypoints the robots published (descriptors are not sent to the
        observer), in camera order; ``cleaning`` the team's consistency stage.

    Raises
    ------
    InputError
        A ``knn:K`` graph (it is chosen from every image's features at once: over zenoh give
        a graph kind or file).
    """
    if comm_edges is None:
        raise InputError(f"--graph {config.graph}: knn:K chooses neighbours from every image's "
                         "features at once; with --transport zenoh give line, ring, ring2, complete, "
                         "seq:K or a graph file")
    team = images_team(config, views, comm_edges)
    n = team.n
    with timer.stage("team", f"{n} robot processes over zenoh"):
        run = _launch_team(team, workdir)
        timer.note(f"{len(run.results)} of {n} robots published; "
                   f"process start {run.start_s:.2f} s")
    if keep_run is not None:
        keep_run.append(run)
    return images_of_run(config, views, team, run)


def images_team(config, views, comm_edges):
    """The loopback team of ``run-images --transport zenoh``: one robot per photograph, its
    path, intrinsics (as loaded, at the downscaled size) and their source, the run's
    feature and resolution options."""
    directory = Path(config.directory).resolve()
    data = {"kind": "images", "images": [str(directory / v.name) for v in views],
            "intrinsics": [np.asarray(v.K, np.float64).tolist() for v in views],
            "intrinsics_known": [bool(v.intrinsics_known) for v in views],
            "intrinsics_source": [str(v.intrinsics_source) for v in views],
            "max_size": config.max_size}
    opts = team_options(config.features, config.max_features, None,
                        merge_radius=photo_merge_radius(config.features, config.resolution,
                                                        config.merge_radius),
                        resolution=config.resolution,
                        contrast_threshold=config.contrast_threshold,
                        rootsift=bool(config.rootsift),
                        budget_after_merge=bool(config.budget_after_merge),
                        threshold_px=config.threshold_px, matcher=config.matcher)
    n = len(views)
    return make_team(f"images-{n}", comm_edges, data, opts, n=n)


def _robots(lost, views) -> str:
    """``"robot 1 (b.jpg)"``, or ``"robots 1 (b.jpg) and 2 (c.jpg)"``: every robot of a
    message, by id and image."""
    names = [f"{k} ({views[k].name})" for k in lost]
    return f"robot {names[0]}" if len(names) == 1 else f"robots {listed(names)}"


def images_of_run(config, views, team, run) -> ImagesRobots:
    """What the robots of a photo ``team`` published in ``run`` (launched here, or observed by
    :mod:`pipeline.team.observe`), as the ``images`` job's result.

    Raises
    ------
    TeamError
        A robot did not publish (the run of photographs needs every camera's keypoints): one
        line naming it and saying that nothing was written.
    """
    from pipeline.types import Features

    n = team.n
    lost = sorted(set(range(n)) - set(run.results))
    if lost:
        its = "its process" if len(lost) == 1 else "each one's process"
        raise TeamError(f"{_robots(lost, views)} did not publish a result: {its} "
                        "ended or was cut off first (its own log or stderr says why); "
                        "a run of photographs needs every robot's keypoints, so nothing was "
                        "written: run the team again")
    feats = []
    for i in range(n):
        kp = run.results[i][1]["keypoints"].reshape(-1, 2)
        feats.append(Features(kp, np.zeros((len(kp), 0), np.float32),
                              np.zeros(len(kp), np.float32), config.features))
    matches, links = links_of_team(team, run.results)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    res = consistency_of_team(team, run.results, links, m, run.killed)
    cleaning = CleaningResult(ledger_from_consistency(res, conflictive_links(m, links)),
                              dict(res.stats), fusion_stats=dict(FUSION_SKIPPED))
    return ImagesRobots(feats, matches, links, cleaning, team_summary(run))


def resolve_links_file(links_csv, fpc, comm_edges, options: dict | None = None, *,
                       kill=None, workdir=None, keep_run: list | None = None, links=None,
                       data_extra: dict | None = None,
                       stop_at_loss: bool = False) -> ConsistencyResult:
    """``resolve --transport zenoh``: each robot reads its own rows of ``links_csv``.

    ``links_csv``: one file the robots share, or a list of one file per robot holding only
    the rows that touch it (then each robot reads only its own file); the links of the
    result are ``links`` when given, else the shared file's rows in order, or the per-robot
    files' links each once, sorted. ``data_extra``: more keys of the team's ``data`` (e.g. the
    robots' ``keypoints`` and ``cameras``, :mod:`pipeline.team.teamfile`). ``stop_at_loss``:
    the team is stopped as soon as a robot's process ends without publishing
    (:func:`pipeline.team.launcher.launch_team`), which raises :class:`RobotsLost` naming
    it."""
    from pipeline.inputs.linkscsv import read_links_csv

    fpc = [int(v) for v in np.asarray(fpc).reshape(-1)]
    edges = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
    per_robot = isinstance(links_csv, (list, tuple))
    paths = [str(Path(p).resolve()) for p in links_csv] if per_robot \
        else str(Path(links_csv).resolve())
    data = {"kind": "links", "links": paths, "features_per_camera": fpc, **(data_extra or {})}
    team = make_team("resolve", edges, data, options, n=len(fpc))
    run = _launch_team(team, workdir, kill=kill, stop_at_loss=stop_at_loss)
    if keep_run is not None:
        keep_run.append(run)
    if run.stopped_by:
        gone = run.stopped_by
        raise RobotsLost(f"the robot process{'es' if len(gone) > 1 else ''} of camera"
                         f"{'s' if len(gone) > 1 else ''} {', '.join(map(str, gone))} ended "
                         "without publishing; the team was stopped", lost_robots(run),
                         _spent_by(run))
    if links is not None:
        pass
    elif per_robot:
        links = _union_links([read_links_csv(p).links for p in links_csv])
    else:
        links = read_links_csv(links_csv).links
    res = consistency_of_team(team, run.results, links, fpc, run.killed)
    res.stats["team"] = team_summary(run)
    return res


def resolve(features_per_camera, comm_edges, links, faults, resolution, ids, evidence=None):
    """``resolve --transport zenoh``: the consistency stage as one robot process per camera.

    The links to make consistent (kept rows, compact ids, with their quality: the evidence
    of the evidence rule) go to one file per robot in a temporary team folder, each with the
    rows that touch that robot: a robot reads only its own (:func:`resolve_links_file`).
    ``ids`` is not needed: the robots are the cameras of the compact layout. ``evidence``
    (``link_weight`` and ``keypoints``, as the simulator's stage takes them,
    :func:`pipeline.stages.consistency_stage`; ``clean-db``): each robot also gets its own
    links' weights (``data.weights``) and its own keypoints, with no pose. Returns
    ``(ConsistencyResult, faults section or None)``; the result's links are ``links``.
    """
    from pipeline.commgraph import comm_edges_for
    from pipeline.faults import fault_report
    from pipeline.runfolder import scratch_folder

    m = features_per_camera
    written = links
    if evidence is None and not np.isfinite(links.quality).all():
        # a quality a links file cannot carry (-inf: an assignment's pair whose nearest
        # alternative is at distance 0, run-landmarks): the robots get the weights the
        # simulator derives from the qualities, in their weights files, and a placeholder
        # quality they do not read
        from pipeline.matching.link_evidence import ratio_llr
        from pipeline.types import Links

        evidence = {"link_weight": ratio_llr(1.0 - links.quality), "keypoints": None}
        written = Links(links.cam_i, links.feat_i, links.cam_j, links.feat_j,
                        np.where(np.isfinite(links.quality), links.quality, 0.0))
    with scratch_folder("resolve-team-") as work:
        paths = write_robot_links(Path(work), written, len(m))
        extra = {}
        if evidence is not None:
            extra["weights"] = write_robot_weights(Path(work), links, evidence["link_weight"],
                                                   len(m))
            if evidence.get("keypoints") is not None:
                extra["keypoints"] = _write_robot_keypoints(Path(work), evidence["keypoints"])
                extra["cameras"] = [None] * len(m)
        res = resolve_links_file(paths, m, comm_edges_for(m, links, comm_edges),
                                 team_options(faults=faults, resolution=resolution),
                                 workdir=work, links=links, data_extra=extra)

    fault_section = None
    if (faults is not None and faults.any) or res.stats["faults"]["robots_lost"]:
        fault_section = fault_report(faults or FaultConfig(), res)
    return res, fault_section


def online_stage(features_per_camera, links, resolution, *, solve_small_sets=True,
                 keypoints=None, projections=None, gather_conflictive=False,
                 gather_free=False, history=None, kill=None) -> ConsistencyResult:
    """The rule's stage of one online step (``run-formation --steps N --transport zenoh``): one
    robot process per frame of the step's sub-problem that has a link there, over Zenoh, each
    reading its own rows of the sub-problem's links (:func:`resolve_links_file`); neighbours
    are the frames sharing a link, as in the simulator.

    The frames are the stage's cameras, as in the simulator (:mod:`pipeline.consistency.
    engines.online`); a frame without a link in the sub-problem takes no part (it has
    nothing to send) and the evidence rule's bundle budget is the one of all the
    sub-problem's frames, as the simulator computes it, so both decide alike. With
    ``gather_conflictive`` / ``gather_free`` (the online stage's ``robots_solve``) the robots
    also solve the small sets at their roots (:mod:`pipeline.consistency.roots`): each then
    holds its own keypoints (its keypoints file) and its own projection (its
    ``data.cameras`` entry ``P``, null where unknown), as the simulator's robots do. Without
    them the robots hold links and their quality only: the evidence rule's small
    conflictive sets must then be left to the caller (``solve_small_sets=False``).

    ``history``: one :class:`~pipeline.consistency.history.HistoryInputs` per frame; each
    robot process then runs the step's history check after the rule on its own inputs (its
    file of ``data.history``, :func:`pipeline.team.robot._robot_history`), and
    ``stats['history']`` holds the links they cut (``cut``), the check's rounds and its
    messages and bytes (``counted``: already in the stage's counts).

    ``kill``: ``(robot, status, delay_s)``, fault injection (tests, bench): ``kill -9`` of the
    team's robot ``robot`` (the ``robot``-th camera with a link) ``delay_s`` s after it
    published ``status`` (:func:`pipeline.team.launcher.launch_team`).

    Raises
    ------
    RobotsLost
        A robot process was lost during the stage (its process ended or its neighbours wrote
        it off), its camera named in ``cameras``: the survivors' result is not returned (its
        links would read as the rule's cuts); the online stage decides what follows
        (:meth:`pipeline.consistency.engines.online.OnlineAssociation.add_step`).
    """
    from pipeline.commgraph import comm_edges_for
    from pipeline.consistency.rules import get_rule
    from pipeline.consistency.setlists import bundle_budget
    from pipeline.runfolder import scratch_folder
    from pipeline.types import Links

    rule = get_rule(resolution)
    leaves = rule.set_lists   # a rule whose small sets the caller may solve (evidence)
    gather = leaves and (gather_conflictive or gather_free)
    if leaves and solve_small_sets and not gather_conflictive:
        raise InputError(f"the {rule.name} rule over zenoh in an online run: its small "
                         "conflictive sets are solved at their roots (the online stage's "
                         "gathering, by its robots with robots_solve); drop --no-gather")
    m = np.asarray(features_per_camera, dtype=np.int64).reshape(-1)
    used = np.unique(np.concatenate([links.cam_i, links.cam_j]))
    where = np.searchsorted(used, np.arange(len(m)))
    sub = Links(where[links.cam_i], links.feat_i, where[links.cam_j], links.feat_j,
                links.quality)
    # a robot lost while the sets are solved at their roots or in the history check: the
    # others name it and publish (the step starts the team again), they do not fail
    opts = {**team_options(resolution=rule.name), "restarted_on_loss": True}
    if leaves:
        opts.update(solve_small_sets=False, bundle_budget=bundle_budget(len(m)))
    if gather:
        opts.update(gather_conflictive=bool(gather_conflictive), gather_free=bool(gather_free))
    with scratch_folder("online-step-") as work:
        paths = write_robot_links(Path(work), sub, len(used))
        extra = {}
        if gather and keypoints is not None:
            P = [None if projections is None or projections[g] is None else
                 {"P": np.asarray(projections[g], np.float64).tolist()} for g in used.tolist()]
            extra = {"keypoints": _write_robot_keypoints(Path(work),
                                                         [keypoints[g] for g in used.tolist()]),
                     "cameras": P}
        if history is not None:
            extra["history"] = _write_robot_history(Path(work), history, used, where)
        kept: list = []
        try:
            res = resolve_links_file(paths, m[used], comm_edges_for(m[used], sub, None), opts,
                                     workdir=work, links=sub, data_extra=extra, keep_run=kept,
                                     kill=kill, stop_at_loss=True)
        except RobotsLost as e:  # the team's cameras are the sub-problem's used images
            raise RobotsLost(f"{processes_lost(int(used[c]) for c in e.cameras)} "
                             "during an online step's consistency stage",
                             used[e.cameras].tolist(), e.stats) from e
    lost = lost_robots(kept[0], res.stats.get("faults", {}).get("robots_lost"))
    if lost:  # its links would read as the rule's cuts: the caller decides what follows
        raise RobotsLost(f"{processes_lost(int(used[k]) for k in lost)} during an "
                         "online step's consistency stage",
                         used[lost].tolist(), _spent(res))
    if history is not None:
        from pipeline.consistency.history import HCUT, HECHO, HGO, HLAB, HTOK, HUP

        kinds = (HLAB, HTOK, HECHO, HGO, HUP, HCUT)

        heads = [h for h, _ in kept[0].results.values()]
        res.stats["history"] = dict(
            cut=np.unique(np.concatenate(
                [np.zeros(0, np.int64)] + [np.asarray(a.get("history_cut", []), np.int64)
                                           for _, a in kept[0].results.values()])),
            rounds=int(max((h["history"]["rounds"] for h in heads if h.get("history")),
                           default=0)),
            messages=int(sum(res.stats["messages_by_kind"].get(k, 0) for k in kinds)),
            bytes=int(sum(res.stats["bytes_by_kind"].get(k, 0) for k in kinds)),
            counted=True)
    _count_acted(res, rule, sub, used, m, kept[0], history is not None)
    if leaves:
        res.stats["bundle_budget"] = int(opts["bundle_budget"])
    if gather:  # the phase of the sets solved at their roots, as the simulator reports it
        from pipeline.consistency.roots import CUTS, GBUNDLE, TOKEN

        kinds = (TOKEN, GBUNDLE, CUTS)
        res.stats["roots"] = dict(
            rounds=int(max((ph.get("rounds", 0) for ph in res.stats["per_iteration"]
                            if ph.get("phase") == "roots"), default=0)),
            messages=int(sum(res.stats["messages_by_kind"].get(k, 0) for k in kinds)),
            bytes=int(sum(res.stats["bytes_by_kind"].get(k, 0) for k in kinds)))
    return res


def _spent_by(run) -> dict:
    """What the robots of a team that published counted (messages, bytes, rounds): a team
    stopped at a loss publishes only what its robots had published by then."""
    heads = [h for h, _ in run.results.values()]
    return dict(messages=int(sum(h["counters"]["messages"] for h in heads)),
                bytes=int(sum(h["counters"]["bytes"] for h in heads)),
                rounds=int(max((h["counters"].get("round", 0) for h in heads), default=0)))


def _spent(res) -> dict:
    """What a team's run spent (messages, bytes, rounds), from its result's figures."""
    st = res.stats
    return dict(messages=int(st.get("messages", 0)), bytes=int(st.get("bytes", 0)),
                rounds=int(st.get("detection_rounds", 0)) + int(st.get("resolution_rounds", 0)))


def _count_acted(res, rule, sub, used, m, run, history: bool) -> None:
    """``conflictive_features`` and ``conflictive_sets`` of the stage's first record, as the
    simulator counts them
    (:mod:`pipeline.consistency.engines.driver`): for a rule with a detection, the team's
    conflictive features after its first detection (the sum of each robot's own); for a whole
    stage without one, the features with a link the rule cut (history cuts apart). The robots'
    logs give one robot's phases only (the online step read 0 or one robot's count, and went
    negative once the cuts of the sets solved at their roots were taken off it)."""
    if rule.detection:
        acted = 0
        for head, _ in run.results.values():
            det = [p for p in head.get("run", {}).get("phases", [])
                   if p.get("phase") == "detection"]
            acted += int(det[0].get("conflictive_features", 0)) if det else 0
    else:
        cut = np.flatnonzero(res.deleted)
        if history:
            cut = np.setdiff1d(cut, np.asarray(res.stats["history"]["cut"], np.int64))
        off = np.concatenate([[0], np.cumsum(m[used])])
        acted = int(np.unique(np.r_[off[sub.cam_i[cut]] + sub.feat_i[cut],
                                    off[sub.cam_j[cut]] + sub.feat_j[cut]]).size)
    # the sets Alg. 1 resolved, as the simulator counts them (each set once, at its root):
    # the sum of the sets each robot rooted in its resolution passes (one robot's phases
    # carry no such count, and the step read 0)
    rooted = sum(int(p.get("roots", 0)) for head, _ in run.results.values()
                 for p in head.get("run", {}).get("phases", []) if p.get("phase") == "resolution")
    if not res.stats["per_iteration"]:
        res.stats["per_iteration"].append({})
    for p in res.stats["per_iteration"]:  # a pass's own count (consistency_of_team): the
        p.pop("conflictive_sets", None)   # step sums the records, so the total goes once
    res.stats["per_iteration"][0]["conflictive_features"] = acted
    res.stats["per_iteration"][0]["conflictive_sets"] = rooted


def online_fusion(views, features, links, comm_edges, *, track_labels=None, kill=None):
    """The fusion of one online step's changed tracks (``run-formation --steps N --transport
    zenoh``): one robot process per frame, over Zenoh, each running the fusion code of a batch
    formation run (:func:`pipeline.team.robot.robot_main`, step 6: :class:`pipeline.fusion.robot.
    FusionRobot`) on what it alone holds: its own rows of ``links`` (its links file), its own
    keypoints (its keypoints file) and its own camera ``K, R, t`` (its ``data.cameras`` entry,
    :mod:`pipeline.team.teamfile`), and the comm edges that touch it.

    The robots first name their tracks themselves: the consistency stage of ``paper-labels``
    (the label flooding of :mod:`pipeline.consistency.labels`, then Alg. 1) on the links,
    which are conflict-free (the kept links of the online association), so it only detects:
    each feature's track is named by the smallest global feature id of its association set
    (Prop. 3.5, :meth:`pipeline.consistency.robot.Robot.final_tracks`); the flooding sends
    one label per feature and link where the rows of ``paper`` send whole sets
    (``bench/online_team.py``: 7.68 MB against 81.08 MB on formation d, 3 steps). The
    simulator's job (:func:`pipeline.fusion.landmarks.fuse_tracks`) takes the same names as
    ``track_labels`` (the caller computes them: the robots' max-c draws hang on them), so both
    decide alike; here ``track_labels``, when given, is checked against the names the robots
    learnt.

    Returns
    -------
    FusionResult
        ``cut_links`` over ``links``, the fused landmarks and their tracks (numbered as
        :func:`pipeline.fusion.landmarks.tracks_of`), each robot's observations; ``stats`` those
        of :func:`pipeline.team.assemble.fusion_of_team`, with the naming detection's
        ``naming_rounds``, ``naming_messages`` and ``naming_bytes`` and the ``team`` summary.

    ``kill``: ``(robot, status, delay_s)``, fault injection (tests, bench), as
    :func:`online_stage` takes it.

    Raises
    ------
    InputError
        A view without a pose.
    RobotsLost
        A robot did not publish (its process ended or was killed) or its neighbours wrote it
        off (it fell silent), named in ``cameras``.
    TeamError
        The detection cut a link (the links were not conflict-free), or a robot named a track
        otherwise than ``track_labels``.
    """
    from pipeline.fusion.landmarks import FusionResult, require_posed_views
    from pipeline.runfolder import scratch_folder

    require_posed_views(views, features)
    n = len(views)
    m = np.array([len(f) for f in features], dtype=np.int64)
    cameras = [{"K": np.asarray(v.K, np.float64).tolist(),
                "R": np.asarray(v.R, np.float64).tolist(),
                "t": np.asarray(v.t, np.float64).reshape(3).tolist()} for v in views]
    opts = team_options(resolution="paper-labels", fusion=True)
    with scratch_folder("online-fusion-") as work:
        folder = Path(work)
        paths = write_robot_links(folder, links, n)
        data = {"kind": "links", "links": [str(p) for p in paths],
                "features_per_camera": m.tolist(),
                "keypoints": _write_robot_keypoints(folder, [f.keypoints for f in features]),
                "cameras": cameras}
        team = make_team("online-fusion", comm_edges, data, opts, n=n)
        run = _launch_team(team, work, kill=kill, stop_at_loss=True)
    res = consistency_of_team(team, run.results, links, m, run.killed) \
        if not run.stopped_by else None
    # a robot whose process ran on but fell silent (a host suspended or cut off) is written
    # off by its neighbours, who name it: their naming cut its links robot-lost
    lost = lost_robots(run, None if res is None else res.stats["faults"]["robots_lost"])
    if lost:
        raise RobotsLost(f"{_robots(lost, views)} of the fusion team did not publish a "
                         "result, or its neighbours wrote it off", lost)
    if res.deleted.any():
        k = int(np.flatnonzero(res.deleted)[0])
        raise TeamError(f"the fusion team's detection cut link ({links.cam_i[k]},"
                        f"{links.feat_i[k]})-({links.cam_j[k]},{links.feat_j[k]}): the links "
                        "handed to fusion must be conflict-free (kept links)")
    off = np.concatenate([[0], np.cumsum(m)])
    obs = [(i, a) for i, (_, a) in sorted(run.results.items())]
    if track_labels is not None:
        want = np.asarray(track_labels, np.int64).reshape(-1)
        for i, a in obs:
            feat = off[i] + a["fusion_feat"].astype(np.int64)
            if not np.array_equal(want[feat], a["fusion_names"].astype(np.int64)):
                raise TeamError(f"robot {i} named its tracks otherwise than track_labels")
    ledger = ledger_from_consistency(res)
    stats, points, track_ids, groups = fusion_of_team(team, run.results, ledger, m)
    stats.update(naming_rounds=int(res.stats["detection_rounds"]),
                 naming_messages=int(res.stats["messages"]),
                 naming_bytes=int(res.stats["bytes"]), team=team_summary(run))
    cut = np.asarray(ledger.reason == "fusion-outlier", bool)
    # each robot's observations (its features in a fused track), tracks as tracks_of numbers them
    from pipeline.fusion.landmarks import tracks_of

    uf, _ = tracks_of(m, links)
    cam = np.concatenate([np.full(len(a["fusion_feat"]), i, np.int64) for i, a in obs]) \
        if obs else np.zeros(0, np.int64)
    feat = np.concatenate([a["fusion_feat"].astype(np.int64) for _, a in obs]) \
        if obs else np.zeros(0, np.int64)
    estimated = np.concatenate([a["fusion_estimated"].astype(bool) for _, a in obs]) \
        if obs else np.zeros(0, bool)
    outlier = np.concatenate([a["fusion_outlier"].astype(bool) for _, a in obs]) \
        if obs else np.zeros(0, bool)
    point_of = np.full(int(off[-1]), -1, dtype=np.int64)  # the fused point of each feature
    for k, g in enumerate(groups):
        point_of[g] = k
    return FusionResult(points=points, track_ids=track_ids, obs_track=uf[off[cam] + feat],
                        obs_cam=cam, obs_feat=feat, obs_estimated=estimated,
                        obs_inlier=~outlier, cut_links=cut, stats=stats,
                        obs_point=point_of[off[cam] + feat])


def links_of_run(team, run) -> ConsistencyResult:
    """The consistency stage of a ``links`` team observed by :mod:`pipeline.team.observe`:
    the links are those the robots published in their link tables (each link once, sorted
    by ``(cam_i, feat_i, cam_j, feat_j)``: the observer reads no links file), the decisions
    those of their logs. Each link's quality is the one its robots published with their link
    tables (``link_quality``, where their links file has a quality column,
    :func:`links_quality_published`), else 1."""
    from pipeline.types import Links

    parts = []
    for i, (_, a) in sorted(run.results.items()):
        nbr = a["link_nbr"].astype(np.int64)
        r, s = a["link_r"].astype(np.int64), a["link_s"].astype(np.int64)
        lo = i < nbr
        q = a["link_quality"].astype(np.float64) if "link_quality" in a \
            else np.ones(len(nbr))
        parts.append(Links(np.where(lo, i, nbr), np.where(lo, r, s), np.where(lo, nbr, i),
                           np.where(lo, s, r), q))
    links = _union_links(parts)
    res = consistency_of_team(team, run.results, links, team.data["features_per_camera"],
                              run.killed)
    res.stats["team"] = team_summary(run)
    return res


def links_quality_published(run) -> bool:
    """Whether every robot of an observed ``links`` team that published gave its links'
    quality (``link_quality``: its links file has a quality column), so that the links of
    :func:`links_of_run` carry the file's quality."""
    return bool(run.results) and all("link_quality" in a for _, a in run.results.values())


#: the environment variable that says where the robots of an online run's teams are forked
#: from: ``run`` (default) one zygote for every team of the run, ``team`` a zygote of each
#: team's own (the robot program imported again for each team; ``bench/online_team.py``
#: compares the two)
ZYGOTE_ENV = "FORMATION_MATCH_ZYGOTE"
ZYGOTE_CHOICES = ("run", "team")


def zygote_per_run() -> bool:
    """Whether an online run's teams share one zygote (:data:`ZYGOTE_ENV`).

    Raises
    ------
    InputError
        Another value than :data:`ZYGOTE_CHOICES`, named.
    """
    import os

    value = os.environ.get(ZYGOTE_ENV, "run").strip() or "run"
    if value not in ZYGOTE_CHOICES:
        raise InputError(f"{ZYGOTE_ENV}={value!r}: choose one of {', '.join(ZYGOTE_CHOICES)} "
                         "(run: one zygote for every team of an online run, the default; "
                         "team: one per team), or unset it")
    return value == "run"


#: the environment variable that says where the robots of every team the jobs start run:
#: unset or ``loopback`` (default), processes of this machine on its loopback; ``netns``, each
#: robot on a host of its own, a Linux network namespace with one cable per comm edge of its
#: team (:func:`pipeline.team.netns.launch_team_on_hosts`; needs root and iproute2);
#: ``netns:RATE``, every cable capped at ``RATE`` (tc's form: ``1mbit``, ``256kbit``;
#: ``bench/online_team.py`` runs an online run so)
HOSTS_ENV = "FORMATION_MATCH_HOSTS"


def team_launcher():
    """The function that starts a team of the jobs (``launch_team``'s arguments and result):
    :func:`pipeline.team.launcher.launch_team`, or on hosts of their own as
    :data:`HOSTS_ENV` says.

    Raises
    ------
    InputError
        A value of :data:`HOSTS_ENV` other than ``loopback``, ``netns`` or ``netns:RATE``,
        or a bad rate, named; ``netns`` where namespaces cannot be made (the reason named).
    """
    import os

    from pipeline.team.netns import check_rate, launch_team_on_hosts

    value = os.environ.get(HOSTS_ENV, "").strip()
    if value in ("", "loopback"):
        return launch_team
    kind, colon, rate = value.partition(":")
    if kind != "netns":
        raise InputError(f"{HOSTS_ENV}={value!r}: choose loopback (the default: robot processes "
                         "on this machine's loopback), netns (each robot in a network namespace "
                         "of its own, one cable per comm edge) or netns:RATE (the cables capped, "
                         "e.g. netns:1mbit), or unset it")
    if colon:
        check_rate(rate, f"{HOSTS_ENV}={value!r}")
    why = _namespaces_unavailable()
    if why is not None:
        raise InputError(f"{HOSTS_ENV}={value!r}: robots on hosts of their own need network "
                         f"namespaces, which cannot be made here ({why}); unset it to run them "
                         "on this machine's loopback")
    return functools.partial(launch_team_on_hosts, rate=rate if colon else None)


@functools.lru_cache(maxsize=1)
def _namespaces_unavailable() -> str | None:
    """:func:`pipeline.team.netns.unavailable`, asked once per process (it makes a namespace)."""
    from pipeline.team.netns import unavailable

    return unavailable()


def _launch_team(team, workdir=None, **options):
    """Start ``team`` as :data:`HOSTS_ENV` says (:func:`team_launcher`)."""
    return team_launcher()(team, workdir, **options)


def job_teams():
    """The context a command's jobs run in (:func:`pipeline.runs.transports.team_limits`):
    every team they start forks its robots from one zygote
    (:func:`pipeline.team.launcher.shared_zygote`; ``run-formations`` starts one per
    formation, an online run three per step), unless :data:`ZYGOTE_ENV` says ``team``.
    :data:`HOSTS_ENV` is checked here, before any work (its robots are not forked: each is
    its own interpreter on its own host)."""
    team_launcher()
    return shared_zygote() if zygote_per_run() else contextlib.nullcontext()


@contextlib.contextmanager
def online_robots():
    """What the robots of an online run keep from step to step (:func:`online_match`): a
    folder per robot, under a temporary folder removed at the end of the run. Every team the
    run starts (three per step: matching, the rule's stage, fusion) forks its robots from one
    zygote (:func:`pipeline.team.launcher.shared_zygote`): the robot program is imported
    once for the run, not once per team (unless :data:`ZYGOTE_ENV` says ``team``)."""
    from pipeline.runfolder import scratch_folder

    with scratch_folder("online-robots-") as store, job_teams():
        yield store


def online_match(views, t: int, n: int, window: int, edges_up, store, *, features: str,
                 max_features, merge_radius: float, feature_options: dict,
                 match_options: dict, kill=None):
    """An online step's matching as robot processes (:mod:`pipeline.team.online_match`): each
    robot extracts its new frame's features, keeps its window's in its own folder under
    ``store`` (kept by the caller from step to step), exchanges with the robots it talks to
    at step ``t`` (``edges_up``) the features they match with, and matches its own pairs.

    Returns ``(features, links, stats)``: the new frames' :class:`~pipeline.types.Features`
    in robot order (keypoints and scales; the descriptors stay with their robot: ``(N, 0)``),
    the step's links in global frame ids in the simulator's order (pairs in increasing
    order, as :func:`pipeline.matching.pairs.match_edges` returns them), and the team's
    messages, bytes and wall time with the bytes of each new frame's descriptors
    (``descriptor_bytes``, robot order) and the most bytes of features a robot holds
    (``held_bytes_max``: its window's frames and those its neighbours sent it).

    A team that loses a robot (its process ends, or a frame never reaches a neighbour that
    matches it: that robot publishes it ``missing``) is started again, once, each robot
    sending its window frames again (``data.resend``); ``stats`` then counts the lost
    team's messages and bytes too, ``attempts`` the teams started and ``robots_lost`` the
    robots each lost team lost. A robot the team started again loses too does not stop the
    mission: the step goes on with what the others published. A robot that did not publish
    has its new frame *void* (no features, ``frames_void``; no robot matches it at a later
    step either: :mod:`pipeline.team.online_match`, ``data.void``, kept in ``store``), and
    the step's pairs no robot matched (those of the void frames, and those whose frame
    never reached the robot that matches them) have no links (``pairs_unmatched``). The
    first team of the next step then sends its window frames again too (what a lost robot
    had sent, or had been sent, may not have been kept). ``kill``: ``(robot, status,
    delay_s)``, fault injection (tests, bench) on the first team, as
    :func:`pipeline.team.launcher.launch_team` takes it; a list of them applies one per team
    started (``None`` for none).

    Raises
    ------
    TeamError
        Every robot of the team started again was lost (nothing to go on with), or the
        robots matched pairs :func:`pipeline.matching.pairs.step_pairs` does not list.
    """
    from pipeline.matching.pairs import step_pairs
    from pipeline.runfolder import scratch_folder, write_json_atomic
    from pipeline.team.online_match import write_frame
    from pipeline.types import Features, Links, PairMatches

    store = Path(store)
    frames = []
    for i in range(n):
        path = store / "cameras" / f"frame-{t * n + i}.npz"  # what robot i's camera delivered
        write_frame(path, views[t * n + i])
        frames.append(str(path))
    # what earlier steps' losses left: void frames (still in the window) and whether the
    # robots' records of what they sent can be trusted
    losses_path = store / "losses.json"
    losses = json.loads(losses_path.read_text()) if losses_path.exists() else {}
    void = sorted(int(f) for f in losses.get("void", ()) if int(f) // n > t - window)
    data = {"kind": "online-match", "step": int(t), "window": int(window), "frames": frames,
            "store": [str(store / f"robot-{i}") for i in range(n)], "void": void}
    opts = team_options(features, max_features, None, merge_radius=merge_radius,
                        **{k: v for k, v in feature_options.items()
                           if k in ("contrast_threshold", "rootsift", "budget_after_merge")},
                        threshold_px=match_options.get("threshold_px", 1.0),
                        matcher=match_options.get("matcher", "opencv"))
    kills = list(kill) if isinstance(kill, list) else [kill, None]
    lost_log, spent = [], dict(messages=0, bytes=0, rounds=0)
    for attempt in (0, 1):  # a team that lost a robot is started again, once
        resend = bool(attempt) or bool(losses.get("resend", False))
        team = make_team(f"online-match-{t}", np.asarray(edges_up, np.int64).reshape(-1, 2),
                         {**data, "resend": resend}, opts, n=n)
        # the team started again goes on without a robot lost again, so its robots wait
        # for a silent neighbour's start no longer than for a round's word: forked at once
        # from a warm zygote, a robot that is there answers in well under a second
        opts = {**opts, "start_timeout_s": float(team.options["round_timeout_s"])}
        with scratch_folder("online-match-") as work:
            run = _launch_team(team, work, kill=kills[attempt] if attempt < len(kills) else None,
                               stop_at_loss=attempt == 0)
        named: dict = {}  # robot -> the robots whose frame of it never came
        for j, (h, _) in run.results.items():
            for f in h.get("missing", ()):
                named.setdefault(int(f) % n, []).append(int(j))
        lost = lost_robots(run, named)
        if not lost:
            break
        lost_log.append(lost)
        if attempt == 0:
            for k, v in _spent_by(run).items():
                spent[k] += v
    if lost and not run.results:
        raise TeamError(f"every robot of step {t}'s matching team was lost twice (robot "
                        f"{lost[0]} first); no frame of the step is known: run it again")
    feats, desc_bytes, held, matches = [], [], [], {}
    new_void = []
    for i in range(n):
        if i not in run.results:  # lost by the team started again: its frame is void
            new_void.append(t * n + i)
            feats.append(Features(np.zeros((0, 2), np.float32),
                                  np.zeros((0, 0), np.float32),
                                  np.zeros(0, np.float32), features))
            desc_bytes.append(0)
            continue
        header, arrays = run.results[i]
        kp = arrays["keypoints"].reshape(-1, 2)
        feats.append(Features(kp, np.zeros((len(kp), 0), np.float32), arrays["scales"],
                              features))
        desc_bytes.append(int(header["descriptor_bytes"]))
        held.append(int(header["held_bytes"]))
        for pr in header["pairs"]:
            a, b = int(pr["a"]), int(pr["b"])
            matches[(a, b)] = PairMatches(
                a, b, arrays[f"pairs_{a}_{b}"].reshape(-1, 2), arrays[f"ratio_{a}_{b}"],
                arrays[f"eperr_{a}_{b}"], int(pr["n_putative"]), str(pr["reason"]))
    frames = np.arange((t + 1) * n)
    want = [tuple(p) for p in step_pairs(frames % n, frames // n, t, window, edges_up).tolist()]
    was_void = set(void)
    want = [p for p in want if p[0] not in was_void and p[1] not in was_void]
    if set(matches) - set(want):
        extra = sorted(set(matches) - set(want))[0]
        raise TeamError(f"step {t}: the robots matched frame pair {extra}, which the step "
                        "does not have")
    if not lost and sorted(matches) != want:
        raise TeamError(f"step {t}: the robots matched {len(matches)} frame pairs, the step "
                        f"has {len(want)}")
    unmatched = [p for p in want if p not in matches]
    for a, b in unmatched:  # its robot, or a frame of it, was lost: no links this step
        matches[(a, b)] = PairMatches(a, b, np.zeros((0, 2), np.int32),
                                      np.zeros(0, np.float32), np.zeros(0, np.float32),
                                      0, "robot-lost")
    write_json_atomic(losses_path, {"void": sorted(f for f in was_void | set(new_void)
                                                   if f // n > t + 1 - window),
                                    "resend": bool(lost_log)})
    links = Links.from_matches([matches[p] for p in want])
    summary = team_summary(run)
    this = _spent_by(run)
    stats = {"messages": this["messages"] + spent["messages"],
             "bytes": this["bytes"] + spent["bytes"],
             "wall_s": float(summary["wall_s"]), "pairs": len(want) - len(unmatched),
             "descriptor_bytes": desc_bytes,
             "held_bytes_max": max(held, default=0), "attempts": attempt + 1,
             "robots_lost": lost_log, "frames_void": new_void,
             "pairs_unmatched": len(unmatched)}
    return feats, links, stats
