"""Command-line options shared by several commands, each defined once with one check.

``--features`` and ``--max-features`` (the feature stage, :mod:`pipeline.matching.features`),
``--seed`` and ``--size`` (the rendered formations of :mod:`data_synth`), ``--resolution``
(the consistency stage's resolution rule, :mod:`pipeline.consistency.rules`), ``--transport``,
``--team-timeout`` and ``--round-timeout`` (where the robots run, how long a team may run
and a robot waits for a silent neighbour, :mod:`pipeline.runs.transports`) and
``--merge-radius`` (near-duplicate keypoints).
"""

from __future__ import annotations

import argparse
import math

from pipeline.errors import InputError
from pipeline.validate import render_size

__all__ = ["count_argument", "given_options", "seed_argument", "positive_argument", "add_feature_options", "add_online_options", "check_online_options", "online_run_summary", "add_scene_options",
           "add_resolution_option", "add_transport_option", "add_merge_radius_option",
           "team_timeout", "round_timeout", "transport_time_limit",
           "add_memory_option", "add_overwrite_and_memory_options",
           "feature_options", "parse_size", "size_argument"]


def add_feature_options(p: argparse.ArgumentParser, photos: bool = False) -> None:
    """``--features`` and ``--max-features``; check them with :func:`feature_options`.

    ``--features`` lists only the methods this OpenCV build offers. With ``photos``,
    ``--max-features`` defaults to ``auto`` (scaled with each image,
    :func:`pipeline.matching.features.photo_max_features`).
    """
    from pipeline.matching.features import available_methods

    default = "colmap-sift" if photos else "sift"
    p.add_argument("--features", default=default,
                   help=f"feature method: {'|'.join(available_methods())} (the ones this build "
                        f"offers; colmap-sift is COLMAP's SIFT; default {default})")
    if photos:
        p.add_argument("--max-features", default="auto", metavar="N|auto",
                       help="features per image; auto (default): with colmap-sift COLMAP's "
                            "own 8192 at every size, with the other methods 2000 per 640x480 "
                            "pixels, from 2000 to 8192. COLMAP's SIFT applies its budget to whole "
                            "scale levels, each location with up to two orientations: an image "
                            "may keep somewhat more locations than N")
    else:
        p.add_argument("--max-features", type=int, default=2000,
                       help="features per image (default 2000)")


def add_scene_options(p: argparse.ArgumentParser) -> None:
    """``--seed`` and ``--size WIDTHxHEIGHT`` of rendered formations; parse the size with
    :func:`parse_size`."""
    p.add_argument("--seed", type=int, default=0, help="scene and noise seed (default 0)")
    p.add_argument("--size", default="640x480", help="image size WIDTHxHEIGHT (default 640x480)")


def add_resolution_option(p: argparse.ArgumentParser, default: str | None = None, *,
                          links_only: bool = False, faults: bool = False) -> None:
    """``--resolution RULE``: a rule of :mod:`pipeline.consistency.rules` (Alg. 1 of the
    paper, the evidence-aware rule, ...); ``default`` None: the registry's
    ``DEFAULT_RESOLUTION``, or ``DEFAULT_LINKS_RESOLUTION`` for a job that receives links
    only (``links_only``); ``faults``: the command has the fault flags of
    :func:`pipeline.faults.add_fault_arguments`, which the help then names."""
    from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION, DEFAULT_RESOLUTION, RULES

    if default is None:
        default = DEFAULT_LINKS_RESOLUTION if links_only else DEFAULT_RESOLUTION

    p.add_argument("--resolution", choices=tuple(RULES), default=default,
                   help="how the robots cut conflictive sets: "
                        + "; ".join(rule.help for rule in RULES.values())
                        + f" (default {default}"
                        + ("; with a fault flag, --drop-prob, --delay-rounds, --crash or "
                           "--switching-topology, a rule that is not fault-tolerant gives way to "
                           "the fault-tolerant Alg. 1, with a warning" if faults else "")
                        + ")")


#: the defaults of :func:`add_online_options` (``--hold``'s: ``window - 1``, by the job)
ONLINE_DEFAULTS = {"window": 3, "batch_every": 0}


def add_online_options(g, flag: str) -> None:
    """``--window``, ``--hold`` and ``--batch-every`` of an online job (``flag`` the option that
    turns it on, named in the help): :class:`pipeline.consistency.engines.online.
    OnlineAssociation`'s window and hold, and the batch reruns beside it."""
    g.add_argument("--window", type=int, default=None,
                   help=f"with {flag}: steps of frames a robot holds and matches against "
                        f"(default {ONLINE_DEFAULTS['window']})")
    g.add_argument("--hold", type=int, default=None,
                   help=f"with {flag}: steps a frame's links stay open after it leaves the "
                        "matching window (default window - 1; 0: final at once)")
    g.add_argument("--batch-every", type=int, default=None,
                   help=f"with {flag}: also run the batch stage from scratch on all links "
                        f"every K steps (default {ONLINE_DEFAULTS['batch_every']}: at the last "
                        "step only)")


def refuse_online_options(args, flag: str) -> None:
    """InputError when ``--window``, ``--hold`` or ``--batch-every`` is given to a job that is
    not online (they would be ignored without a word); ``flag`` turns the online job on."""
    for name in ("window", "hold", "batch_every"):
        if getattr(args, name) is not None:
            raise InputError(f"--{name.replace('_', '-')} applies to an online job only; add "
                             f"{flag} or drop it")


def check_online_options(args) -> None:
    """InputError naming a bad ``--window``, ``--hold`` or ``--batch-every``
    (:func:`add_online_options`); fills in the defaults of those not given."""
    for name, value in ONLINE_DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if args.window < 1:
        raise InputError(f"--window {args.window}: expected a number of steps >= 1")
    if args.hold is not None and args.hold < 0:
        raise InputError(f"--hold {args.hold}: expected a number of steps >= 0 (0: a frame's "
                         "links are final once it leaves the window)")
    if args.batch_every < 0:
        raise InputError(f"--batch-every {args.batch_every}: expected steps >= 0")


def online_run_summary(report: dict, out, first_line: str, no_rerun: bool) -> int:
    """Print an online job's summary (``first_line``, then the files written to ``out``) and
    its report's warnings (:func:`pipeline.outcome.flag_online`), and return its exit status:
    0, or 3 when a step ended with a conflict."""
    from pipeline.outcome import exit_status

    print(first_line)
    print(f"run written to {out}/ (report.json, links.csv, images.csv, link_steps.csv"
          + ("" if no_rerun else ", recording.rrd") + ")")
    return exit_status(report)  # 3 when a step ended with a conflict (flag_online)


def add_transport_option(p: argparse.ArgumentParser) -> None:
    """``--transport NAME``: where the robots run, one of :mod:`pipeline.runs.transports`
    (shared by the commands that run the robots), ``--team-timeout S``, the seconds each
    team of robot processes may run, and ``--round-timeout S``, the seconds of silence after
    which a robot writes a neighbour off (the team's ``round_timeout_s``; its start
    handshake's ``start_timeout_s`` and ``round_limit_s`` at least twice that,
    :func:`pipeline.team.teamfile.round_timeout_options`); both through
    :func:`transport_time_limit`, which the command line applies around the command."""
    from pipeline.runs.transports import transport_help, transport_names
    from pipeline.team.launcher import TEAM_TIMEOUT_S
    from pipeline.team.teamfile import DEFAULT_OPTIONS

    p.add_argument("--transport", default="sim", choices=transport_names(),
                   help=transport_help())
    p.add_argument("--team-timeout", default=None, metavar="S",
                   help="with robot processes (--transport zenoh): seconds each team may run "
                        f"before it is stopped (default {TEAM_TIMEOUT_S:g}; an online run "
                        "starts teams every step, each gets S); raise it for a large team on a "
                        "slow machine")
    p.add_argument("--round-timeout", default=None, metavar="S",
                   help="with robot processes (--transport zenoh): seconds of silence after "
                        "which a robot writes a neighbour off (default "
                        f"{DEFAULT_OPTIONS['round_timeout_s']:g}); the start handshake waits "
                        f"max({DEFAULT_OPTIONS['start_timeout_s']:g}, 2 x S) s and a round at "
                        f"most max({DEFAULT_OPTIONS['round_limit_s']:g}, 2 x S) s; every team "
                        "of the run gets it; raise it when robots on a loaded machine write "
                        "healthy neighbours off")
    # the command line runs the command within these (pipeline.__main__._run)
    p.set_defaults(_within=transport_time_limit)


#: the longest ``--team-timeout``, in seconds (a week): beyond it, a typo
MAX_TEAM_TIMEOUT_S = 7 * 86400.0


def team_timeout(value) -> float:
    """``--team-timeout``'s ``value`` in seconds: a finite number above 0, at most
    :data:`MAX_TEAM_TIMEOUT_S`.

    >>> team_timeout("1800")
    1800.0
    """
    from pipeline.validate import positive_number

    return positive_number(value, "--team-timeout", "seconds", MAX_TEAM_TIMEOUT_S,
                           "the seconds each team of robot processes may run", "1800")


#: the longest ``--round-timeout``, in seconds (an hour of silence): beyond it, a typo
MAX_ROUND_TIMEOUT_S = 3600.0


def round_timeout(value) -> float:
    """``--round-timeout``'s ``value`` in seconds: a finite number from
    :data:`pipeline.team.teamfile.MIN_ROUND_TIMEOUT_S` to :data:`MAX_ROUND_TIMEOUT_S` (the start handshake's and a round's limits, twice it, stay
    within a team file's bound, :data:`pipeline.team.teamfile.MAX_TIMEOUT_S`).

    >>> round_timeout("45")
    45.0
    """
    from pipeline.team.teamfile import MIN_ROUND_TIMEOUT_S
    from pipeline.validate import positive_number

    v = positive_number(value, "--round-timeout", "seconds", MAX_ROUND_TIMEOUT_S,
                        "the seconds of silence after which a robot writes a neighbour off",
                        "120")
    if v < MIN_ROUND_TIMEOUT_S:
        raise InputError(f"--round-timeout {value!r}: shorter than {MIN_ROUND_TIMEOUT_S:g} s; "
                         "a live robot beats every 0.2 s at most, so every robot would write "
                         "its neighbours off as silent and the team would keep no link: give "
                         "a few seconds or more, e.g. --round-timeout 120")
    return v


def transport_time_limit(args):
    """The context manager a command runs in (:func:`pipeline.__main__._run`): with
    ``--team-timeout S`` (:func:`add_transport_option`), every team of robot processes it
    starts is stopped after ``S`` seconds; with ``--round-timeout S``, the robots of every team
    it starts write a neighbour off after ``S`` seconds of silence
    (:func:`pipeline.runs.transports.team_limits`, which also enters the transport's own
    context for a command's teams: over Zenoh one zygote forks the robots of them all); a
    command without ``--transport``: nothing.

    Raises
    ------
    InputError
        A bad ``S`` (:func:`team_timeout`, :func:`round_timeout`), or an option with a
        transport that starts no team (``--transport sim``); ``--team-timeout`` is checked
        first. Both are checked here, before the command; the context is entered when it runs.
    """
    import contextlib

    limit = getattr(args, "team_timeout", None)
    silence = getattr(args, "round_timeout", None)
    if not hasattr(args, "transport"):
        return contextlib.nullcontext()
    from pipeline.runs.transports import team_limits

    limit = None if limit is None else team_timeout(limit)
    return team_limits(args.transport, limit,
                       None if silence is None else round_timeout(silence))


def add_merge_radius_option(p: argparse.ArgumentParser, online: str | None = None,
                            photos: bool = False) -> None:
    """``--merge-radius PX``: keypoints of one image closer than this are one feature;
    ``online``: the command's option of an online run, which keeps 0.5 px (named in the
    help); ``photos``: a command on photographs, where colmap-sift keeps 0.5 px
    (:func:`pipeline.stages.photo_merge_radius`; a rendered formation takes the rule's
    radius with every feature method, :func:`pipeline.stages.merge_radius_for`)."""
    p.add_argument("--merge-radius", type=float, default=None, metavar="PX",
                   help="keypoints of one image closer than this are one feature (default: "
                        "the rule's, 2 px (the truth tolerance) with --resolution evidence or "
                        "sync, 0.5 px with paper and paper-labels"
                        + ("; 0.5 px with colmap-sift, as COLMAP keeps nearby DoG extrema apart"
                           if photos else ", whatever --features")
                        + (f"; 0.5 px with {online}" if online else "") + ")")


def feature_options(args) -> tuple[str, int | None]:
    """The checked ``(method, max_features)`` of :func:`add_feature_options`' options
    (``max_features`` is ``None`` for ``auto``).

    Raises
    ------
    InputError
        An unknown method, one this OpenCV build lacks, or fewer than :data:`~pipeline.matching.features.MIN_FEATURES`
        or more than :data:`~pipeline.matching.features.MAX_FEATURES`.
    """
    from pipeline.matching.features import METHODS, available_methods, check_method

    method = str(args.features).lower()
    if method not in METHODS:
        raise InputError(f"--features {args.features!r}: choose one of "
                         f"{', '.join(available_methods())} (unknown feature method "
                         f"{args.features!r})")
    check_method(method)
    if str(args.max_features).lower() == "auto":
        return method, None
    from pipeline.matching.methods import max_features

    args.max_features = max_features(args.max_features)
    return method, args.max_features


def count_argument(text: str) -> int:
    """An argparse ``type`` for a count of at least one (the bench scripts' ``--repeat``,
    ``--steps``, ...): argparse's one-line error names the option and the value.

    >>> count_argument("3")
    3
    """
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number of at least 1")
    return value


def given_options(parser: argparse.ArgumentParser, argv) -> set[str]:
    """The ``dest`` of every option ``argv`` sets itself (rather than leaving it to its
    default): a bench's ``--quick`` picks small values only for the options not given, e.g.
    ``--quick --frames 4``. Parse ``argv`` with ``parser`` first (its errors are reported
    there).

    >>> p = argparse.ArgumentParser()
    >>> _ = p.add_argument("--n", type=int, default=3)
    >>> _ = p.add_argument("--quick", action="store_true")
    >>> sorted(given_options(p, ["--quick"]))
    ['quick']
    """
    unset = object()
    probe = argparse.Namespace(**{a.dest: unset for a in parser._actions
                                  if a.dest is not argparse.SUPPRESS})
    parser.parse_args(argv, namespace=probe)  # argparse sets no default on a dest already set
    return {dest for dest, value in vars(probe).items() if value is not unset}


def positive_argument(text: str) -> float:
    """An argparse ``type`` for a finite number above 0 (the bench scripts' time and memory
    caps: ``--timeout``, ``--cap-s``, ``--cap-gb``): argparse's one-line error names the option
    and the value.

    >>> positive_argument("1.5")
    1.5
    """
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a finite number above 0")
    return value


def seed_argument(text: str) -> int:
    """An argparse ``type`` for a seed (the bench scripts' ``--seed``, ``--seeds``,
    ``--team-seeds``, ...): the commands' seed check (:func:`pipeline.validate.seed`), as
    argparse's one-line error naming the option and the value.

    >>> seed_argument("7")
    7
    """
    from pipeline.validate import seed

    try:
        return seed(text, "seed")
    except InputError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: " + str(exc).split(": ", 1)[1]) from None


def size_argument(text: str) -> str:
    """An argparse ``type`` for ``--size``: ``text`` unchanged when :func:`parse_size` reads
    it, else argparse's one-line error with :func:`parse_size`'s message (the bench scripts,
    which hand ``--size`` on to the commands).

    >>> size_argument("320x240")
    '320x240'
    """
    try:
        parse_size(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` → ``(640, 480)``; InputError on anything else.

    >>> parse_size("320x240")
    (320, 240)
    """
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    return render_size(w, h, text)


def add_overwrite_and_memory_options(p: argparse.ArgumentParser, outputs: str) -> None:
    """``--overwrite`` (replace existing ``outputs``, else refuse) and ``--max-memory-gb`` (the
    memory budget of the job, :mod:`pipeline.budget`; checked by
    :func:`pipeline.budget.limit_gb`), shared by the commands that clean a user's matches
    (``resolve``, ``clean-db``, ``clean-h5``)."""
    p.add_argument("--overwrite", action="store_true",
                   help=f"replace {outputs} if they exist (default: refuse)")
    add_memory_option(p)


def add_memory_option(p: argparse.ArgumentParser) -> None:
    """``--max-memory-gb``: the memory budget of the job (:mod:`pipeline.budget`; checked by
    :func:`pipeline.budget.limit_gb`)."""
    from pipeline.budget import DEFAULT_LIMIT_GB

    p.add_argument("--max-memory-gb", default=DEFAULT_LIMIT_GB, metavar="GB",
                   help="refuse inputs whose run would need more memory than this, before "
                        "allocating it (estimate, see pipeline.budget; default "
                        f"{DEFAULT_LIMIT_GB:g})")
