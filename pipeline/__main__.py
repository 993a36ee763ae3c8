"""Command line: ``python -m pipeline <command> ...``.

Each command lives in ``pipeline/commands/<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> int``. Only the module of the command being run is imported (its arguments are
defined on demand), so ``python -m pipeline --help`` loads no OpenCV, SciPy, pycolmap or Rerun.

Exit codes: 0 done; 2 bad input, a file that cannot be read or written, a team of robot
processes that did not finish (one line on stderr naming the robot, nothing written), or a
distributed stage that ran past its bound of rounds (one line naming it); 3 the run finished
but its result is not conflict-free (written, flagged in the report, one line on stderr); 130
interrupted (Ctrl-C; nothing half-written); 143 terminated (SIGTERM: ``kill``, ``timeout``; it
cleans up as a Ctrl-C does; 129 for a SIGHUP, a closed terminal). A closed stdout pipe (``| head -3``) ends the
command quietly with 0.
"""

from __future__ import annotations

import os
import sys

from pipeline.errors import clean_up_on_terminate, exit_quietly_on_interrupt, run_interruptibly

if __name__ == "__main__":  # run as a program: from here on, before the imports below
    exit_quietly_on_interrupt("formation-match")
    clean_up_on_terminate()

import argparse  # noqa: E402
import atexit  # noqa: E402
import contextlib  # noqa: E402
import errno  # noqa: E402
import importlib  # noqa: E402
import logging  # noqa: E402
import select  # noqa: E402
import threading  # noqa: E402
from collections.abc import Callable, Iterable  # noqa: E402

from pipeline.errors import InputError, StageStalledError, TeamError, one_line  # noqa: E402
from pipeline.outcome import recording_warnings  # noqa: E402

# command name -> (module, one-line help)
COMMANDS = {
    "match-formation": ("match_formation", "render a formation, match neighbours, print Table III rows"),
    "run-formation": ("run_formation", "full pipeline on a rendered formation, writes a run folder"),
    "run-formations": ("run_formations", "run formations a-d and print the paper-style tables"),
    "resolve": ("resolve", "make your own links conflict-free (links.csv in, links.csv out)"),
    "run-images": ("run_images", "full pipeline on a folder of real photographs"),
    "clean-db": ("clean_db", "remove inconsistent matches from a COLMAP database"),
    "run-landmarks": ("run_landmarks", "labelled-landmark benchmark (e.g. CMU hotel): match, "
                      "resolve, score pairwise against the labels"),
    "clean-h5": ("clean_h5", "remove inconsistent matches from hloc's features.h5/matches.h5"),
    "robot": ("robot", "run one robot of a team over Zenoh (TEAM.json)"),
    "observe": ("observe", "collect the results of a team's robots started elsewhere and "
                "write its run folder (TEAM.json)"),
}


def _command_module(module: str):
    """The command's module, or None if this build does not ship it."""
    try:
        return importlib.import_module(f"pipeline.commands.{module}")
    except ModuleNotFoundError as exc:
        if exc.name != f"pipeline.commands.{module}":
            raise
        return None


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is at the time of each message."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value):
        pass


class _OneLineWarnings(logging.Formatter):
    """The message alone; a warning (or worse) on one line (:func:`pipeline.errors.one_line`),
    the progress lines as they are."""

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        return one_line(text) if record.levelno >= logging.WARNING else text


def configure_logging(quiet: bool = False) -> None:
    """Messages of the ``pipeline`` loggers go to stderr as plain lines; ``quiet`` keeps only
    warnings and errors (and turns progress bars off, see :mod:`pipeline.progress`)."""
    log = logging.getLogger("pipeline")
    if not any(getattr(h, "_formation_match", False) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(_OneLineWarnings("%(message)s"))
        handler._formation_match = True
        log.addHandler(handler)
        log.propagate = False
    log.setLevel(logging.WARNING if quiet else logging.INFO)


def build_parser(commands: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser; the arguments of ``commands`` (default: all) are defined.

    The other commands are listed with their help line only, which is all the top-level
    ``--help`` shows; defining a command's arguments imports its module.
    """
    from pipeline import __version__

    full = set(COMMANDS) if commands is None else set(commands)
    parser = argparse.ArgumentParser(
        prog="formation-match",
        description="formation-match: consistent decentralized multi-camera data association. "
                    "Also run as 'python -m pipeline'.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    quiet = argparse.ArgumentParser(add_help=False)
    quiet.add_argument("-q", "--quiet", action="store_true",
                       help="print only warnings, errors and the final result (no stage lines, "
                            "no progress bars)")
    quiet.add_argument("--version", action="version", version=f"formation-match {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text, parents=[quiet])
        p.set_defaults(_module=module)
        if name not in full:
            continue
        mod = _command_module(module)
        if mod is None:
            p.set_defaults(_missing=True)
            continue
        mod.add_arguments(p)
    return parser


def _requested_command(argv: list[str]) -> str | None:
    """The command named on the command line (the first positional argument), if any.

    The top-level parser's only options (``-h``, ``--version``) take no value, so the first argument that is not an
    option is the command; a ``-h`` before it asks for the top-level help.
    """
    for arg in argv:
        if arg in ("-h", "--help"):
            return None
        if not arg.startswith("-"):
            return arg if arg in COMMANDS else None
    return None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    command = _requested_command(argv)
    return interruptible(command or "formation-match", lambda: _run(argv, command))


def interruptible(command: str, run: Callable[[], int]) -> int:
    """``run()``'s exit code; a Ctrl-C while it runs ends it with one line on stderr naming
    ``command`` (and the outputs already in place, if any) and exit code 130, never a
    traceback. Also used by the other programs of the project (``python -m viz.saved_run``)."""
    if "pipeline.runfolder" in sys.modules:  # a new command: nothing of it in place yet
        sys.modules["pipeline.runfolder"].forget_outputs_in_place()
    paths_printable()
    return run_interruptibly(command, run)


def paths_printable() -> None:
    """Let stdout print every path as the file system names it. In a UTF-8 locale such as
    en_US.UTF-8 Python's stdout refuses the bytes of a name that is not UTF-8 (Latin-1),
    which Python reads as surrogates: the line naming such an output ended the command in a
    UnicodeEncodeError traceback once the output was written. Those bytes are now written
    back as they are (Python's ``surrogateescape``, its own choice in the C locale)."""
    stream = sys.stdout
    if getattr(stream, "errors", None) == "strict" and hasattr(stream, "reconfigure"):
        with contextlib.suppress(ValueError, OSError):  # a closed or detached stream
            stream.reconfigure(errors="surrogateescape")


def _run(argv: list[str], command: str | None) -> int:
    """Parse, import the command (its libraries load here) and run it; errors of the user's
    input as one line (exit 2)."""
    parser = build_parser([command] if command else [])
    args = parser.parse_args(argv)
    configure_logging(quiet=bool(getattr(args, "quiet", False)))
    if getattr(args, "_missing", False):
        parser.error(f"command {args.command!r} is not available in this build")
    mod = importlib.import_module(f"pipeline.commands.{args._module}")
    try:
        # what the command runs within, set by its parser: --team-timeout and --round-timeout
        # of a command that takes --transport (checked first)
        within = getattr(args, "_within", None)
        with within(args) if within is not None else contextlib.nullcontext(), \
                recording_warnings():  # the report keeps the warnings printed (outcome)
            return int(mod.run(args) or 0)
    except (InputError, TeamError) as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except StageStalledError as exc:
        print(f"error: {exc}, a bound a correct run never reaches: the inputs break an "
              "assumption no check caught (e.g. the two ends of a link read it otherwise), or "
              "the stage has a defect", file=sys.stderr)
        return 2
    except OSError as exc:
        if isinstance(exc, BrokenPipeError) and _stdout_closed():
            return _stdout_gone()
        print(f"error: {_where(exc)}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"error: {args.command} ran out of memory; try a smaller input", file=sys.stderr)
        return 2


#: errors of writing: a copy (``shutil.copyfile``) that fails so is named by its destination
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS}


def _where(exc: OSError) -> str:
    """The file(s) an OSError names, for its one line: a copy's error names both files (the
    source first), a full disk only the destination, the file on that disk."""
    if exc.filename2 is not None:
        if exc.errno in _WRITE_ERRNOS:
            return f"{exc.filename2}: "
        return f"{exc.filename} -> {exc.filename2}: "
    return f"{exc.filename}: " if exc.filename else ""


def _stdout_closed() -> bool:
    """stdout is a pipe whose reader has gone (``| head``): writing to it fails."""
    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll(), no file descriptor
        return False


def _stdout_gone() -> int:
    """The end of a command whose stdout reader stopped reading (``| head -3``): quietly, as
    Unix tools end, with exit code 0 (what the reader took is what it asked for; the same code
    as when the pipe is found closed only at the final flush). What is still buffered for
    stdout is discarded."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (AttributeError, OSError, ValueError):
        pass
    return 0


def entry() -> None:
    """Run :func:`main` as a program and end the process with its exit code.

    When a command returns, everything it writes is already on disk: run folders and files are
    written to a temporary sibling, closed and renamed into place (the Rerun recording is
    disconnected, which writes its footer, before the rename), and robot processes have been
    waited for. What is left is the interpreter's teardown, which frees every object of every
    imported module (NumPy, OpenCV, SciPy, pycolmap, Rerun) one by one: 0.1-0.25 s of a 1.8 s
    default ``run-formation`` on a 2-core machine, for nothing the user sees. So, after
    flushing stdout and stderr and running the exit handlers (``atexit``: logging's flush,
    the libraries' own), the process ends at once (:func:`os._exit`).

    The normal exit is kept where something still runs after :func:`main` returns: an exception
    that escapes it (a bug: traceback and usual clean-up), a profiler or tracer (``python -m
    cProfile``, coverage), which writes its data afterwards, and any thread of the program
    that is not a daemon, which the normal exit waits for.
    """
    exit_quietly_on_interrupt("formation-match")  # a Ctrl-C that escapes main (module notes)
    clean_up_on_terminate()  # a kill ends through the clean-up, as a Ctrl-C does
    code = main()
    others = [t for t in threading.enumerate()
              if t is not threading.main_thread() and not t.daemon]
    if sys.gettrace() is not None or sys.getprofile() is not None or others:
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        if stream is None:  # started with that descriptor closed (``>&-``): Python sets None
            continue
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (``| head``) or a closed stream
            pass
    atexit._run_exitfuncs()  # what the normal exit runs first; then only the teardown is left
    os._exit(code)


if __name__ == "__main__":
    entry()
