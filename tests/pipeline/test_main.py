"""Command-line conventions: the program names itself, has --version, --quiet, and the
licence file matches the package metadata."""

import tomllib
from pathlib import Path

import pytest

from pipeline import __version__
from pipeline.__main__ import build_parser, configure_logging, main
from pipeline.progress import StageTimer

ROOT = Path(__file__).resolve().parents[2]


def test_help_names_the_program(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert capsys.readouterr().out.startswith("usage: formation-match")


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"formation-match {__version__}"


def test_every_command_takes_quiet():
    parser = build_parser()
    for argv in (["clean-db", "x.db", "--out", "y.db", "--quiet"],
                 ["run-images", "DIR", "--graph", "complete", "-q"]):
        assert parser.parse_args(argv).quiet


def test_quiet_hides_stage_lines_and_keeps_warnings(capsys):
    try:
        configure_logging(quiet=False)
        with StageTimer().stage("features", "sift"):
            pass
        err = capsys.readouterr().err
        assert "[features] sift ..." in err and "done in" in err
        configure_logging(quiet=True)
        timer = StageTimer()
        with timer.stage("features"):
            timer.warn("few images registered")
        err = capsys.readouterr().err
        assert "[features]" not in err and "few images registered" in err
    finally:
        configure_logging(quiet=False)


def test_licence_file_matches_pyproject():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "MIT"
    assert "LICENSE" in meta.get("license-files", [])
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text
