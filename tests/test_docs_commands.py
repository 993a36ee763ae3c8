"""Every command line README.md quotes is accepted as written: a bench's options by its own
parser, a ``python -m pipeline`` / ``formation-match`` line by the command's parser, a ``make``
line names a target and variables of the Makefile. Only the arguments are parsed: no bench,
no command runs. Users copy these lines; an option renamed in the code and not in the README
stops them at the first word."""

import argparse
import contextlib
import importlib.util
import io
import re
import shlex
import sys
from pathlib import Path
from unittest import mock

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("benchload", ROOT / "tests" / "bench" / "benchload.py")
benchload = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(benchload)

#: a one-letter value stands for the reader's own (``--seed S``, one run per seed)
PLACEHOLDER = re.compile(r"[A-Z]")


def quoted_lines(text: str) -> list[tuple[int, str]]:
    """(line number, text) of each line of a ``bash`` block (its ``\\`` continuations joined,
    comments dropped) and of each inline code span (wrapped over lines or not)."""
    found = []
    fence = re.compile(r"^```(\w*)\n(.*?)^```", flags=re.M | re.S)
    for block in fence.finditer(text):
        if block.group(1) not in ("bash", "sh"):
            continue
        first = text.count("\n", 0, block.start(2)) + 1
        pending = ""
        for i, line in enumerate(block.group(2).splitlines()):
            line = re.sub(r"(^|\s)#.*$", "", line).rstrip()
            if line.endswith("\\"):
                pending += line[:-1] + " "
                continue
            if (pending + line).strip():
                found.append((first + i, (pending + line).strip()))
            pending = ""
    prose = fence.sub(lambda m: "\n" * m.group(0).count("\n"), text)
    for span in re.finditer(r"`([^`]+)`", prose):
        found.append((prose.count("\n", 0, span.start()) + 1, " ".join(span.group(1).split())))
    return found


def commands(text: str) -> list[tuple[int, str, str, str | None, list[str]]]:
    """(line, command as quoted, kind, bench name, arguments) of each quoted command: kind
    'bench' (``[.venv/bin/]python bench/NAME.py ...`` or ``bench/NAME.py ...``), 'pipeline'
    (``[python] -m pipeline ...``, ``formation-match ...``) or 'make'. A usage synopsis
    (``[--seed N]``) is no command."""
    benches = set(benchload.BENCHES)
    found = []
    for line, quoted in quoted_lines(text):
        for part in re.split(r"\s(?:\||&&|;)\s", quoted):
            if "[" in part:
                continue
            try:
                words = shlex.split(part)
            except ValueError:  # prose with an apostrophe, no command
                continue
            while words and re.fullmatch(r"\w+=\S*", words[0]):  # VAR=value before a command
                words = words[1:]
            if words and re.fullmatch(r"(\S*/)?python3?", words[0]):
                words = words[1:]
            if not words:
                continue
            bench = re.fullmatch(r"(?:bench/)?(\w+)\.py", words[0])
            if bench and bench.group(1) in benches:
                found.append((line, part, "bench", bench.group(1), words[1:]))
            elif words[:2] == ["-m", "pipeline"] or (
                    words[0].endswith("formation-match") and len(words) > 1
                    and re.fullmatch(r"-.*|[a-z][a-z-]*", words[1])):
                rest = words[2:] if words[0] == "-m" else words[1:]
                found.append((line, part, "pipeline", None, rest))
            elif words[0] == "make":
                found.append((line, part, "make", None, words[1:]))
    return found


class _Parsed(Exception):
    pass


def _parse_only(run) -> str | None:
    """None if ``run()`` got through its parser's ``parse_args`` (stopped right there), else
    what the parser printed when it refused."""
    parse = argparse.ArgumentParser.parse_args

    def parsed(self, args=None, namespace=None):
        raise _Parsed(parse(self, args, namespace))

    err = io.StringIO()
    with mock.patch.object(argparse.ArgumentParser, "parse_args", parsed), \
            contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            run()
        except _Parsed:
            return None
        except SystemExit as exc:
            said = err.getvalue().strip()
            if exc.code == 0 or "the following arguments are required" in said:
                return None  # --help; a command named in the text without its inputs
            return said.splitlines()[-1] if said else f"exit {exc.code}"
    return "it never parsed its arguments"


_benches: dict = {}


def refusal(kind: str, name: str | None, args: list[str]) -> str | None:
    """Why ``args`` are refused (the parser's message), or None."""
    args = ["1" if PLACEHOLDER.fullmatch(a) else a for a in args]
    if kind == "make":
        makefile = (ROOT / "Makefile").read_text()
        targets = set(re.findall(r"^([\w-]+):", makefile, flags=re.M))
        for a in args:
            if "=" in a:
                var = a.split("=", 1)[0]
                if not re.search(rf"\$\((value )?{var}\)", makefile):
                    return f"make: the Makefile reads no variable {var}"
            elif a not in targets:
                return f"make: no target {a!r} in the Makefile"
        return None
    if kind == "pipeline":
        from pipeline.__main__ import build_parser

        return _parse_only(lambda: build_parser().parse_args(args))
    if name == "opencv_floor":  # its command line by hand: one image folder, nothing else
        return None if len(args) == 1 else f"expected one IMAGE_DIR, got {args}"
    if name not in _benches:
        _benches[name] = benchload.load_bench(name)
    main = _benches[name].main
    main = getattr(main, "__wrapped__", main)
    if name == "run_formation":  # its main reads sys.argv

        def run():
            with mock.patch.object(sys, "argv", [f"bench/{name}.py", *args]):
                main()
        return _parse_only(run)
    return _parse_only(lambda: main(args))


def refusals(text: str) -> list[str]:
    return [f"README.md line {line}: `{quoted}`: {why}"
            for line, quoted, kind, name, args in commands(text)
            if (why := refusal(kind, name, args)) is not None]


README = (ROOT / "README.md").read_text()


def test_the_readme_quotes_commands_of_every_kind():
    kinds = {kind for _, _, kind, _, _ in commands(README)}
    quoted_benches = {name for _, _, kind, name, _ in commands(README) if kind == "bench"}
    assert kinds == {"bench", "pipeline", "make"}
    # the Benchmarks section lists every bench
    assert quoted_benches >= set(benchload.BENCHES) - {"voting_fig23", "voting_pipeline"}


def test_every_command_the_readme_quotes_is_accepted():
    assert refusals(README) == []


@pytest.mark.parametrize("quoted, edited, message", [
    ("bench/online.py --robots 6 --steps 50 --batch-every 10",
     "bench/online.py --robots 6 --steps 50 --batch-every 10 --bogus",
     "unrecognized arguments: --bogus"),
    ("bench/team_starts.py --repeat 5", "bench/team_starts.py --repeat 0",
     "argument --repeat: '0': expected a whole number"),
    ("python -m pipeline run-formation --steps 20",
     "python -m pipeline run-formation --bogus --steps 20", "unrecognized arguments: --bogus"),
    ("make bench QUICK=1", "make bench QUICK=1 bogus", "no target 'bogus' in the Makefile"),
])
def test_a_quoted_command_the_code_refuses_is_named(quoted, edited, message):
    # the same README with one command given an option or a value its parser refuses
    assert quoted in README
    found = refusals(README.replace(quoted, edited, 1))
    assert len(found) == 1 and message in found[0], found
