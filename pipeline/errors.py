"""User-facing errors: the CLI prints these without a traceback (exit code 2)."""


class InputError(ValueError):
    """Bad user input. The message names the offending value and says what to do."""


class TeamError(RuntimeError):
    """A team of robot processes did not finish: a robot never started, failed or hung (the
    message names it)."""


def caused_by_interrupt(exc: BaseException | None) -> bool:
    """``exc`` is a KeyboardInterrupt, or an error raised because of one (a C++ extension
    interrupted while it loads reports an ImportError, which its package may turn into
    another error: pycolmap's "Cannot import the C++ backend")."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def report_interrupt(command: str) -> int:
    """One line on stderr saying ``command`` was stopped by a Ctrl-C (naming the outputs
    already in place, if any); the exit status of an interrupted command, 130."""
    import sys

    done = []
    if "pipeline.runfolder" in sys.modules:  # else nothing can have been put in place
        done = sys.modules["pipeline.runfolder"].outputs_in_place()
    if done:  # too late to keep them: say which are there, written in full
        names = ", ".join(repr(str(p)) for p in done[:4]) + (", …" if len(done) > 4 else "")
        print(f"interrupted: {command} stopped; already in place, complete: {names}",
              file=sys.stderr)
    else:
        print(f"interrupted: {command} stopped, nothing was written or replaced",
              file=sys.stderr)
    return 130


def one_line_errors(main):
    """A bench's ``main`` (or its entry point) ending as the command line does: an
    :class:`InputError` as one line ``error: …`` on stderr, exit status 2; a Ctrl-C as one
    line ``interrupted: bench/NAME.py stopped …``, exit status 130; no traceback."""
    import functools
    import sys
    from pathlib import Path

    name = f"bench/{Path(main.__code__.co_filename).name}"

    @functools.wraps(main)
    def wrapped(*args, **kwargs) -> int:
        try:
            return run_interruptibly(name, lambda: main(*args, **kwargs))
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    return wrapped


def run_interruptibly(command: str, run) -> int:
    """``run()``'s exit code; a Ctrl-C while it runs (also one a library turned into another
    exception) ends it with :func:`report_interrupt`'s line and exit code 130."""
    try:
        return run()
    except KeyboardInterrupt:
        return report_interrupt(command)
    except Exception as exc:
        if caused_by_interrupt(exc):  # e.g. while a library's C++ part was loading
            return report_interrupt(command)
        raise
