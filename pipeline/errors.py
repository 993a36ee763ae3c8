"""User-facing errors: the CLI prints these without a traceback (exit code 2)."""


class InputError(ValueError):
    """Bad user input. The message names the offending value and says what to do."""


class TeamError(RuntimeError):
    """A team of robot processes did not finish: a robot never started, failed or hung (the
    message names it)."""


def one_line_errors(main):
    """``main(argv=None) -> int`` (a bench's) with an :class:`InputError` printed as the
    command line prints it: one line ``error: …`` on stderr, exit status 2, no traceback."""
    import functools
    import sys

    @functools.wraps(main)
    def wrapped(argv=None) -> int:
        try:
            return main(argv)
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    return wrapped
