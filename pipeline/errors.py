"""User-facing errors: the CLI prints these without a traceback (exit code 2)."""


class InputError(ValueError):
    """Bad user input. The message names the offending value and says what to do."""


class TeamError(RuntimeError):
    """A team of robot processes did not finish: a robot never started, failed or hung (the
    message names it)."""
