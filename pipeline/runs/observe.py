"""The ``observe`` job: the run folder of a team whose robots were started elsewhere.

``formation-match observe --team TEAM.json --out DIR`` listens on the team's observer
endpoint (:mod:`pipeline.team.observe`), collects every robot's published result, and writes
the run folder the one-machine launcher (``--transport zenoh``) writes for the same team:

* ``data.kind == "formation"``: the run folder of ``run-formation`` (``report.json``,
  ``links.csv``, ``sparse/``, ``recording.rrd``), evaluated against the formation's ground
  truth, which the observer renders itself (:func:`pipeline.runs.formation.write_formation_run`
  on :func:`pipeline.runs.transports.zenoh.formation_of_run`). The run's settings are the team
  file's (``data`` and ``options``).
* ``data.kind == "links"``: ``links.csv`` (every link a robot published, each once, sorted
  by ``(cam_i, feat_i, cam_j, feat_j)``; ``status`` and ``reason`` from the robots' logs;
  where the team's links file has a quality column, each link's quality last, as the robots
  published it with their link tables) and
  ``report.json`` (``before`` and ``after`` conflict counts, the resolution's figures, the
  ``team`` section), as ``resolve`` writes them.
* ``data.kind == "images"``: the run folder of ``run-images --transport zenoh`` (the pycolmap
  reconstructions before and after cleaning, ``report.json``, ``links.csv``, ``sparse/``,
  ``recording.rrd``): the observer loads the team's photographs itself, as each robot loads
  its own (:func:`pipeline.team.robot.load_view`), so it needs them on its machine, in one
  folder (that of ``data.images``). As over the launcher, photographs get no fusion.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.progress import StageTimer

__all__ = ["observe_run", "formation_config_of", "images_config_of"]


def formation_config_of(team, out, rerun: bool = True):
    """The :class:`~pipeline.runs.formation.FormationConfig` of a ``formation`` team: its
    data and options as ``run-formation`` would take them."""
    from pipeline.faults import FaultConfig
    from pipeline.runs.formation import FormationConfig

    d, o = team.data, team.options
    drop = float(o.get("drop_prob", 0.0))
    return FormationConfig(
        formation=d.get("formation", "d"), seed=int(d.get("seed", 0)),
        size=tuple(int(v) for v in d.get("size", [640, 480])), features=o["features"],
        max_features=o["max_features"], robots=d.get("robots"), graph=d.get("graph"),
        fusion=bool(o.get("fusion")), out=str(out), rerun=bool(rerun),
        faults=FaultConfig(drop_prob=drop, seed=int(o.get("fault_seed", 0))) if drop else None,
        resolution=str(o["resolution"]), merge_radius=o.get("merge_radius"))


def observe_run(team_path, out, *, timeout_s: float = 600.0, rerun: bool = True,
                timer: StageTimer | None = None, log=None) -> Path:
    """Observe the team of ``team_path`` and write its run folder ``out``; return it.

    Raises
    ------
    InputError
        A bad team file, one without an observer endpoint, or a team of photographs in more
        than one folder or with a photograph missing on this machine (checked before it
        listens).
    TeamError
        A robot failed, or none published within ``timeout_s``
        (:func:`pipeline.team.observe.observe_team`).
    """
    from pipeline.runs.transports import get_transport
    from pipeline.team.launcher import team_summary
    from pipeline.team.observe import observe_team, unreported
    from pipeline.team.teamfile import load_team

    timer = timer or StageTimer()
    team = load_team(team_path)
    kind = team.data["kind"]
    if kind == "online-match":
        raise InputError(f"team {team.name!r} is one step's matching of an online run "
                         "(run-formation --steps N or run-images DIR --sequence with "
                         "--transport zenoh), whose launching process takes its matches; "
                         "there is no run folder to observe")
    if kind in ("formation", "images"):
        # every robot refuses a feature method this build lacks (surf without OpenCV's
        # non-free part) before it starts: the observer would wait --timeout for robots that
        # never start, then call them not started
        from pipeline.matching.features import check_method

        try:
            check_method(team.options["features"])
        except InputError as exc:
            raise InputError(f"team {team.name!r}: option features: {exc}") from None
    if kind == "images":
        folders = {team.resolve_path(p).resolve().parent for p in team.data["images"]}
        if len(folders) != 1:
            raise InputError(f"team {team.name!r}: the observer reads the photographs from one "
                             f"folder, data.images names {len(folders)}; put them in one")
        # the observer loads them once every robot has published (for the reconstructions):
        # a photograph missing here was found only then, the team's whole run lost with it
        from pipeline.outputs import require_input_file

        for i, p in enumerate(team.data["images"]):
            try:
                require_input_file(team.resolve_path(p), f"team {team.name!r}: data.images[{i}]")
            except InputError as exc:
                raise InputError(f"{exc}; the observer needs the team's photographs on "
                                 "this machine too (it loads them for the reconstructions): "
                                 "put them where the team file's paths lead") from None
    if kind == "links" and any(team.options_for(i)["fusion"] for i in range(team.n)):
        raise InputError(f"team {team.name!r}: the observer of a links team writes the "
                         "consistency stage only, not the fusion cuts its robots make; set "
                         "option fusion false (the fusion of a links team runs in "
                         "run-formation --steps N --transport zenoh)")
    from pipeline.commgraph import split_warning

    message = split_warning(team.n, team.comm_edges, "robots", "their features cannot be "
                            "associated across the groups", "add comm_edges to the team file")
    if message:
        timer.warn(message)
    zenoh = get_transport("zenoh").load()
    with timer.stage("observe", f"{team.n} robots of {team.name!r} on {team.observer}"):
        run = observe_team(team, timeout_s=timeout_s, log=log)
        unheard = unreported(team, run.results, run.killed)
        timer.note(f"{len(run.results)} of {team.n} robots published"
                   + (f"; lost: {sorted(run.killed)}" if run.killed else "")
                   + (f" ({unheard} ran to their end: their results did not reach this "
                      "observer)" if unheard else ""))
    summary = {**team_summary(run), "observed": True,
               "lost": sorted(int(k) for k in run.killed), "unreported": unheard}
    if kind == "formation":
        from pipeline.runs.formation import write_formation_run

        config = formation_config_of(team, out, rerun)
        robots = zenoh.formation_of_run(config, team, run, timer)
        robots.extra = {"team": summary}
        return write_formation_run(config, robots.formation, robots.features, robots.matches,
                                   robots.cleaning, timer, extra=robots.extra)
    if kind == "images":
        return _write_images_run(out, team, run, summary, rerun, timer, zenoh)
    return _write_links_run(Path(out), team, zenoh.links_of_run(team, run), summary, timer,
                            quality=zenoh.links_quality_published(run))


def images_config_of(team, out, rerun: bool = True):
    """The :class:`~pipeline.runs.images.ImagesConfig` of an ``images`` team: its options
    as ``run-images --transport zenoh`` hands them to the robots."""
    from pipeline.runs.images import ImagesConfig

    o, d = team.options, team.data
    folder = team.resolve_path(d["images"][0]).resolve().parent
    return ImagesConfig(
        directory=str(folder), graph=f"team {team.name}", max_size=d.get("max_size"),
        features=o["features"], max_features=o["max_features"],
        contrast_threshold=o.get("contrast_threshold"), rootsift=bool(o.get("rootsift")),
        threshold_px=o.get("threshold_px"), budget_after_merge=bool(o.get("budget_after_merge")),
        fusion=False, rerun=bool(rerun), out=str(out), resolution=str(o["resolution"]),
        merge_radius=o.get("merge_radius"), transport="zenoh")


def _write_images_run(out, team, run, summary: dict, rerun: bool, timer: StageTimer,
                      zenoh) -> Path:
    """The ``run-images`` run folder of an observed photo team (module docstring)."""
    from pipeline.runs.images import run_images
    from pipeline.team.robot import load_view

    config = images_config_of(team, out, rerun)
    with timer.stage("load", f"the team's {team.n} photographs"):
        views = [load_view(team, i) for i in range(team.n)]
    edges = np.asarray(team.comm_edges, dtype=np.int64).reshape(-1, 2)

    def robots_job(config, views, comm_edges, timer, graph_from_features):
        robots = zenoh.images_of_run(config, views, team, run)
        robots.team = summary
        return robots

    return run_images(config, timer, loaded=(views, edges), robots_job=robots_job)


def _write_links_run(out: Path, team, res, summary: dict, timer: StageTimer,
                     quality: bool = False) -> Path:
    """``links.csv`` and ``report.json`` of an observed ``links`` team (module docstring);
    ``quality``: ``links.csv`` ends with each link's quality (the robots' links file has
    one)."""
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.consistency.rules import deleted_cases
    from pipeline.inputs.linkscsv import write_links_csv
    from pipeline.outcome import flag_result
    from pipeline.runfolder import atomic_run_folder, write_json_atomic
    from pipeline.stages import ledger_from_consistency

    m = np.asarray(team.data["features_per_camera"], dtype=np.int64)
    st = res.stats
    report = {
        "title": f"team {team.name} (observed)", "cameras": int(m.size),
        "comm_edges": np.asarray(team.comm_edges).tolist(),
        "features_per_camera": m.tolist(), "links": len(res.links),
        "deleted": int(res.deleted.sum()), "resolution_method": st["resolution"],
        "deleted_by_case": {c: int((res.case == c).sum()) for c in deleted_cases(st["resolution"])},
        "before": count_conflicts(AssociationGraph(m, res.links)).as_dict(),
        "after": count_conflicts(AssociationGraph(m, res.kept())).as_dict(),
        "resolution": {k: st[k] for k in ("iterations", "detection_rounds",
                                          "resolution_rounds", "closing_rounds", "messages",
                                          "bytes", "max_robot_memory_bytes") if k in st},
        "faults": st.get("faults"), "team": summary}
    flag_result(report)
    with timer.stage("write", str(out)), atomic_run_folder(out) as tmp:
        write_links_csv(tmp / "links.csv", ledger_from_consistency(res), quality=quality)
        report["timings_s"] = {k: round(v, 4) for k, v in timer.timings.items()}
        write_json_atomic(tmp / "report.json", report)
    return out
