"""Command line: ``python -m pipeline <command> ...``.

Each command lives in ``pipeline/commands/<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported only when their command runs, so ``--help`` is fast.
"""

from __future__ import annotations

import argparse
import importlib
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
    "run-landmarks": ("run_landmarks", "labelled-landmark benchmark (e.g. CMU hotel): match, "
                      "resolve, score pairwise against the labels"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m pipeline",
        description="formation-match: consistent decentralized multi-camera data association.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
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
