"""Command line: ``python -m pipeline <command> ...``.

Each command lives in ``pipeline/commands/<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported only when their command runs, so ``--help`` is fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from pipeline.errors import InputError

# command name -> (module, one-line help)
COMMANDS = {
    "match-formation": ("match_formation", "render a formation, match neighbours, print Table III rows"),
    "run-formation": ("run_formation", "full pipeline on a rendered formation, writes a run folder"),
    "run-formations": ("run_formations", "run formations a-d and print the paper-style tables"),
    "resolve": ("resolve", "make your own links conflict-free (links.csv in, links.csv out)"),
    "run-images": ("run_images", "full pipeline on a folder of real photographs"),
    "clean-db": ("clean_db", "remove inconsistent matches from a COLMAP database"),
    "clean-h5": ("clean_h5", "remove inconsistent matches from hloc's features.h5/matches.h5"),
}


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is at the time of each message."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value):
        pass


def configure_logging(quiet: bool = False) -> None:
    """Messages of the ``pipeline`` loggers go to stderr as plain lines; ``quiet`` keeps only
    warnings and errors (and turns progress bars off, see :mod:`pipeline.progress`)."""
    log = logging.getLogger("pipeline")
    if not any(getattr(h, "_formation_match", False) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("%(message)s"))
        handler._formation_match = True
        log.addHandler(handler)
        log.propagate = False
    log.setLevel(logging.WARNING if quiet else logging.INFO)


def build_parser() -> argparse.ArgumentParser:
    from pipeline import __version__

    parser = argparse.ArgumentParser(
        prog="formation-match",
        description="formation-match: consistent decentralized multi-camera data association. "
                    "Also run as 'python -m pipeline'.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    quiet = argparse.ArgumentParser(add_help=False)
    quiet.add_argument("-q", "--quiet", action="store_true",
                       help="print only warnings, errors and the final result (no stage lines, "
                            "no progress bars)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text, parents=[quiet])
        p.set_defaults(_module=module)
        # argument definitions are cheap; import the module only to define them
        try:
            mod = importlib.import_module(f"pipeline.commands.{module}")
        except ModuleNotFoundError as exc:
            if exc.name != f"pipeline.commands.{module}":
                raise
            p.set_defaults(_missing=True)
            continue
        mod.add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(quiet=bool(getattr(args, "quiet", False)))
    if getattr(args, "_missing", False):
        parser.error(f"command {args.command!r} is not available in this build")
    mod = importlib.import_module(f"pipeline.commands.{args._module}")
    try:
        return int(mod.run(args) or 0)
    except (InputError, FileNotFoundError, NotADirectoryError, PermissionError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
