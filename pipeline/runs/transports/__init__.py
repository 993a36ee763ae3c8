"""The transports a job's robots can run on, by name: the one registry.

A transport is how the robots of a job exchange their messages, and so where they run:
``sim`` — every robot is an object of this process, on the simulated network of
:mod:`pipeline.transport.simulated` (with its faults); ``zenoh`` — one process per robot,
talking over Zenoh (:mod:`pipeline.team`). The command line's ``--transport`` choices and
help, and the runners of :mod:`pipeline.runs`, read this registry; nothing else compares a
transport's name.

What a transport provides: a module (loaded only when a job runs on it, so that ``--help``
loads nothing heavy) with one function per job:

``formation(config, timer, **options) -> FormationRobots`` (:mod:`.results`)
    ``run-formation``: render the formation (or have the robots render their own cameras),
    features, matching, consistency and, with ``config.fusion``, fusion; ``options`` are the
    transport's own (e.g. ``kill``, ``workdir``, ``keep_run``, ``round_timeout_s`` of zenoh).
``images(config, views, comm_edges, timer, graph_from_features) -> ImagesRobots``
    ``run-images``: features and matching of the photographs (``comm_edges`` None: the
    ``knn:K`` graph, chosen by ``graph_from_features(features)``); the consistency stage when
    the robots run it themselves (else ``cleaning`` is None and the runner runs it).
``online_robots()`` and ``online_match(views, t, n, window, edges_up, store, *, features, max_features, merge_radius, feature_options, match_options) -> (features, links, stats)``
    ``run-formation --steps N`` and ``run-images --sequence``: the matching of step ``t``
    (robot ``i``'s new frame is ``views[t * n + i]``; the pairs of
    :func:`pipeline.matching.pairs.step_pairs`, robots talking along ``edges_up``), each robot
    keeping its window's features in ``store`` from step to step (``online_robots()``: a
    context manager giving the store for a whole run). Returns the new frames' features in
    robot order (the keypoints at least), the step's links in global frame ids in the order
    :func:`pipeline.matching.pairs.match_edges` gives them, and ``stats``
    (``pairs`` matched, ``descriptor_bytes`` per new frame; ``messages``, ``bytes`` and
    ``held_bytes_max``, the most bytes of features a robot holds, where counted).
``online_stage(features_per_camera, links, resolution, *, solve_small_sets, keypoints, projections, gather_conflictive, gather_free) -> ConsistencyResult``
    ``run-formation --steps N``: the rule's stage of one step on its sub-problem (the
    step's frames are the cameras, frames sharing a link are neighbours; the online stage
    of :mod:`pipeline.consistency.engines.online` does the rest). The module's
    ``ONLINE_ROBOTS_SOLVE`` (default False) says whether the stage's robots solve the small
    sets at their roots themselves (``gather_*``, :mod:`pipeline.consistency.roots`: robot
    processes must), or the online stage solves them in batch (the simulator).
``online_fusion(views, features, links, comm_edges, *, track_labels) -> FusionResult``
    ``run-formation --steps N`` (fusion on): robust distributed fusion
    (:func:`pipeline.fusion.landmarks.fuse_tracks`, its arguments and result) of the tracks
    one step changed (the frames of those tracks are the robots, frames sharing a link are
    neighbours); ``track_labels``: each feature's track named by the smallest global feature
    id of its set, as robots that detect their sets name them (the max-c draws hang on them).
``resolve(features_per_camera, comm_edges, links, faults, resolution, ids, evidence=None) -> (ConsistencyResult, dict or None)``
    ``resolve``: the consistency stage on a user's links (``ids``: the compact renumbering
    of :mod:`pipeline.inputs.compact`), with the ``faults`` section of the report when
    faults were injected or a robot was lost; also the stage of ``run-landmarks`` and of the
    cleaning commands (``evidence``: the links' weights and the images' keypoints, as
    :func:`pipeline.stages.consistency_stage` takes them; ``clean-db``).

Optional module attributes: ``MAX_ROBOT_PROCESSES`` (the most robots a job may start on this
machine, checked before any work by :func:`check_team_size`), ``COMPACT_IDS`` (``resolve``
runs on the cameras that appear in a link or a comm edge only, :mod:`pipeline.inputs.compact`),
``team_time_limit(seconds)`` (a context manager: every team of robot processes the jobs start
within it is killed after ``seconds``, the commands' ``--team-timeout``) and
``team_round_timeout(seconds)`` (a context manager: the robots of every team the jobs start
within it write a neighbour off after ``seconds`` of silence, the commands'
``--round-timeout``); both through :func:`team_limits`.

A new transport (e.g. ROS 2) is one module with these functions and one
:func:`register` call below (:class:`TransportEntry`: name, help line, loader of the module).
What the jobs hand back is in :mod:`.results`.

May import: the transports' modules (this package), which may import everything below the
runners (:mod:`pipeline.stages`, :mod:`pipeline.team`, ...); never a runner or a command.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["TransportEntry", "TRANSPORTS", "register",
           "unregister", "get_transport", "transport_names", "transport_help",
           "check_team_size", "check_online_team_size", "resolve_alone", "team_limits"]


@dataclass(frozen=True)
class TransportEntry:
    """One transport: its name, its ``--transport`` help and ``load``, which imports and
    returns its module (the one holding the job functions of the module docstring)."""

    name: str
    help: str
    load: Callable


TRANSPORTS: dict[str, TransportEntry] = {}


def register(entry: TransportEntry) -> TransportEntry:
    """Add ``entry`` to the registry (ValueError if its name is taken); return it."""
    if entry.name in TRANSPORTS:
        raise ValueError(f"transport {entry.name!r} is already registered")
    TRANSPORTS[entry.name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove a transport from the registry (tests register toy ones)."""
    del TRANSPORTS[name]


def transport_names() -> tuple[str, ...]:
    """The registered transports' names, in registration order."""
    return tuple(TRANSPORTS)


def get_transport(name: str) -> TransportEntry:
    """The registered transport ``name``.

    Raises
    ------
    InputError
        No transport of that name.
    """
    from pipeline.errors import InputError

    if name not in TRANSPORTS:
        raise InputError(f"transport {name!r}: choose one of {', '.join(TRANSPORTS)}")
    return TRANSPORTS[name]


def check_team_size(name: str, robots: int, what: str,
                    otherwise: str = "start the robots on their own hosts (formation-match robot "
                                     "--team TEAM.json)") -> None:
    """Refuse a job that would start more robots than transport ``name`` allows on this
    machine (its module's ``MAX_ROBOT_PROCESSES``; none: no limit).

    Raises
    ------
    InputError
        ``robots`` above the limit; ``what`` says what they are (e.g. "cameras in the links
        file"), ``otherwise`` what else to do than ``--transport sim``.
    """
    from pipeline.errors import InputError

    cap = getattr(get_transport(name).load(), "MAX_ROBOT_PROCESSES", None)
    if cap is not None and robots > cap:
        raise InputError(f"--transport {name} starts one process per robot on this machine: "
                         f"{robots} {what} would be {robots} processes, at most {cap}; use "
                         f"--transport sim, or {otherwise}")


def team_limits(name: str, team_timeout_s: float | None = None,
                round_timeout_s: float | None = None):
    """The context manager under which a command's jobs run on transport ``name``: the
    module's ``job_teams`` context, if it has one (``zenoh``: one zygote forks the robots of
    every team the command starts); with
    ``team_timeout_s`` (``--team-timeout``), every team of robot processes they start is killed
    after it (the module's ``team_time_limit``); with ``round_timeout_s`` (``--round-timeout``),
    the robots of every team write a neighbour off after that much silence (the module's
    ``team_round_timeout``). None: the option was not given (the transport's own limits).

    Raises
    ------
    InputError
        An option given to a transport that starts no team of processes (``sim``: it would be
        ignored without a word), ``--team-timeout`` named first; a ``--round-timeout`` not
        shorter than the team's limit (given or the default): the team would be stopped
        before a robot could write a silent neighbour off.
    """
    import contextlib

    from pipeline.errors import InputError

    module = get_transport(name).load()
    settings = []  # every option checked before any is set
    for attribute, option, seconds in (("team_time_limit", "--team-timeout", team_timeout_s),
                                       ("team_round_timeout", "--round-timeout",
                                        round_timeout_s)):
        if seconds is None:
            continue
        context = getattr(module, attribute, None)
        if context is None:
            teams = [e.name for e in TRANSPORTS.values()
                     if getattr(e.load(), attribute, None) is not None]
            raise InputError(f"{option} applies to robot processes (--transport "
                             f"{'|'.join(teams)}); --transport {name} starts none: drop it, "
                             f"or add --transport {teams[0]}")
        settings.append((context, seconds))
    if round_timeout_s is not None:
        limit = team_timeout_s if team_timeout_s is not None else module.TEAM_TIMEOUT_S
        if round_timeout_s >= limit:
            given = "" if team_timeout_s is not None else ", its default"
            raise InputError(f"--round-timeout {round_timeout_s:g} is not shorter than "
                             f"--team-timeout {limit:g}{given}: every team would be stopped "
                             "before a robot wrote a silent neighbour off; raise "
                             "--team-timeout above it (or lower --round-timeout)")

    job = getattr(module, "job_teams", None)

    @contextlib.contextmanager
    def within():
        with contextlib.ExitStack() as stack:
            for context, seconds in settings:
                stack.enter_context(context(seconds))
            if job is not None:
                stack.enter_context(job())
            yield

    return within()


def resolve_alone(transport: str, features_per_camera, comm_edges, links, resolution: str,
                  names: list[str], command: str, evidence=None):
    """The rule's stage of a command whose robots run the rule alone (``run-landmarks``,
    ``clean-db``, ``clean-h5``): the ``resolve`` job of ``transport`` (``evidence``: its), on
    the simulator when there is no link (the robots would have nothing to exchange; the same
    empty association on every transport). Returns the :class:`ConsistencyResult`.

    Raises
    ------
    TeamError
        A robot process was lost during the stage: its links would read as cut by the rule,
        leave a cleaned file or lower a benchmark's scores, though nothing judged them; the
        command then writes nothing. ``names``: the image of each robot, by id.
    """
    from pipeline.errors import TeamError, processes_lost

    where = transport if len(links) else "sim"
    res, _ = get_transport(where).load().resolve(features_per_camera, comm_edges, links, None,
                                                 resolution, None, evidence=evidence)
    lost = sorted(int(k) for k in res.stats.get("faults", {}).get("robots_lost", {}))
    if lost:
        raise TeamError(f"{processes_lost(repr(names[k]) for k in lost)} during "
                        f"{command}'s consistency stage; nothing was written: run it again "
                        "(or with --transport sim)")
    return res


def check_online_team_size(name: str, robots: int, window: int, hold: int | None,
                           steps: int) -> None:
    """:func:`check_team_size` of an online run of ``steps`` steps: a step's stage runs one
    robot per frame of the window, ``robots × min(window + hold, steps)`` (``hold`` None: the
    stage's default, :func:`pipeline.consistency.engines.online.default_hold`); a window
    longer than the run holds only the frames the run has."""
    from pipeline.consistency.engines.online import default_hold

    hold = default_hold(window) if hold is None else int(hold)
    # the launching process starts a team for every step: no team file a user could start
    # on other hosts
    check_team_size(name, robots * min(int(window) + hold, int(steps)),
                    "frames in a step's window (robots x min(window + hold, steps): a step's "
                    "stage runs one robot per frame)",
                    otherwise="a shorter --window or --hold")


def transport_help() -> str:
    """The ``--transport`` help: every transport's own line."""
    return "; ".join(f"{e.name}: {e.help}" for e in TRANSPORTS.values()) + \
        "; see README, 'Transports'"


def _sim():
    from pipeline.runs.transports import sim

    return sim


def _zenoh():
    from pipeline.runs.transports import zenoh

    return zenoh


register(TransportEntry(
    "sim", "robots are objects of this process (default, fastest)", _sim))
register(TransportEntry(
    "zenoh", "one process per robot on this machine, talking over Zenoh (fusion on rendered "
             "formations, also online; none on photographs)", _zenoh))
