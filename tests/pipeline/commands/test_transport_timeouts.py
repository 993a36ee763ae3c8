"""``--team-timeout S`` and ``--round-timeout S`` (pipeline.commands.options): on every
command that takes --transport, checked like the other numeric options (one line, exit 2)
before the command runs, refused where the transport starts no team of processes; within
``--round-timeout`` every team the launcher makes carries the timeouts of
pipeline.team.teamfile.round_timeout_options."""

import argparse

import pytest

from pipeline.__main__ import COMMANDS, build_parser, main
from pipeline.commands.options import (
    MAX_ROUND_TIMEOUT_S,
    round_timeout,
    team_timeout,
    transport_time_limit,
)
from pipeline.errors import InputError
from pipeline.team.teamfile import DEFAULT_OPTIONS, MAX_TIMEOUT_S, round_timeout_options

#: each command that takes --transport, with the arguments it needs to parse (never read:
#: the option is checked first)
ARGS = {
    "run-formation": [],
    "run-formations": [],
    "resolve": ["--links", "in.csv", "--out", "out.csv"],
    "run-images": ["photos"],
    "run-landmarks": ["landmarks"],
    "clean-db": ["in.db", "--out", "out.db"],
    "clean-h5": ["--features", "f.h5", "--matches", "m.h5", "--out", "out.h5"],
}


def _options(command):
    sub = build_parser([command])._subparsers._group_actions[0].choices[command]
    return {o for a in sub._actions for o in a.option_strings}


def test_every_command_with_transport_takes_team_timeout():
    with_transport = {c for c in COMMANDS if "--transport" in _options(c)}
    assert with_transport == set(ARGS)
    for command in with_transport:
        assert "--team-timeout" in _options(command), command


#: each option, a value beyond its bound and the example its error gives
OPTIONS = {"--team-timeout": ("1e9", "1800"), "--round-timeout": ("3601", "120")}


@pytest.mark.parametrize("option", sorted(OPTIONS))
@pytest.mark.parametrize("command", sorted(ARGS))
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "0", "-5", "too-large", "ten", ""])
def test_a_bad_timeout_is_one_line_and_exit_2(option, command, value, capsys, tmp_path,
                                              monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing is written: the option is checked first
    too_large, example = OPTIONS[option]
    value = too_large if value == "too-large" else value
    code = main([command, *ARGS[command], "--transport", "zenoh", f"{option}={value}"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"error: {option} {value!r}: ")
    assert f"e.g. {option} {example}" in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("option", sorted(OPTIONS))
@pytest.mark.parametrize("command", sorted(ARGS))
def test_a_timeout_is_refused_on_the_simulator(option, command, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for transport in ([], ["--transport", "sim"]):
        assert main([command, *ARGS[command], *transport, option, "60"]) == 2
        err = capsys.readouterr().err
        assert err == (f"error: {option} applies to robot processes (--transport zenoh); "
                       "--transport sim starts none: drop it, or add --transport zenoh\n")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("text, seconds", [("1800", 1800.0), ("0.5", 0.5), ("1e3", 1000.0)])
def test_team_timeout_reads_seconds(text, seconds):
    assert team_timeout(text) == seconds


def test_the_limit_reaches_launch_team_and_is_restored():
    import argparse

    from pipeline.team import launcher

    args = argparse.Namespace(transport="zenoh", team_timeout="42")
    assert launcher._within["time_limit"] == launcher.TEAM_TIMEOUT_S == 600.0
    with transport_time_limit(args):
        assert launcher._within["time_limit"] == 42.0
    assert launcher._within["time_limit"] == 600.0
    with transport_time_limit(argparse.Namespace(transport="zenoh", team_timeout=None)):
        assert launcher._within["time_limit"] == 600.0
    with pytest.raises(InputError, match="applies to robot processes"):
        transport_time_limit(argparse.Namespace(transport="sim", team_timeout="42"))


def test_every_command_with_transport_takes_round_timeout():
    with_transport = {c for c in COMMANDS if "--transport" in _options(c)}
    assert with_transport == set(ARGS)
    for command in with_transport:
        assert "--round-timeout" in _options(command), command
    assert not any("--round-timeout" in _options(c) for c in set(COMMANDS) - with_transport)


def test_team_timeout_is_checked_first():
    args = argparse.Namespace(transport="zenoh", team_timeout="nan", round_timeout="nan")
    with pytest.raises(InputError, match="^--team-timeout 'nan'"):
        transport_time_limit(args)


@pytest.mark.parametrize("text, seconds", [("45", 45.0), ("1", 1.0), ("3.6e3", 3600.0)])
def test_round_timeout_reads_seconds(text, seconds):
    assert round_timeout(text) == seconds


@pytest.mark.parametrize("command", sorted(ARGS))
@pytest.mark.parametrize("value", ["0.01", "0.1", "0.99"])
def test_a_round_timeout_shorter_than_the_beats_is_refused(command, value, capsys, tmp_path,
                                                           monkeypatch):
    """A robot beats every 0.2 s at most: ``--round-timeout 0.01`` made every robot write
    every neighbour off before a feature crossed, and the run ended with exit 0 and no link
    (its warnings blamed the images). It is refused before the command, naming the value."""
    monkeypatch.chdir(tmp_path)
    code = main([command, *ARGS[command], "--transport", "zenoh", "--round-timeout", value])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"error: --round-timeout {value!r}: shorter than 1 s; ")
    assert "e.g. --round-timeout 120" in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())


def test_the_rule_keeps_the_start_and_round_limits_at_least_twice_the_silence():
    assert round_timeout_options(DEFAULT_OPTIONS["round_timeout_s"]) == {
        k: DEFAULT_OPTIONS[k] for k in ("round_timeout_s", "start_timeout_s", "round_limit_s")}
    assert round_timeout_options(10) == {"round_timeout_s": 10.0, "start_timeout_s": 60.0,
                                         "round_limit_s": 600.0}
    assert round_timeout_options(45) == {"round_timeout_s": 45.0, "start_timeout_s": 90.0,
                                         "round_limit_s": 600.0}
    top = round_timeout_options(MAX_ROUND_TIMEOUT_S)
    assert top == {"round_timeout_s": 3600.0, "start_timeout_s": 7200.0,
                   "round_limit_s": 7200.0}
    assert max(top.values()) <= MAX_TIMEOUT_S  # a team file's own bound


def test_the_timeouts_reach_make_team_and_are_restored():
    from pipeline.team import launcher

    def options(**kw):
        team = launcher.make_team("t", [[0, 1]], {"kind": "links", "links": "l.csv",
                                                  "features_per_camera": [1, 1]}, kw or None)
        return {k: team.options[k] for k in ("round_timeout_s", "start_timeout_s",
                                             "round_limit_s")}

    default = options()
    assert default == {"round_timeout_s": 30.0, "start_timeout_s": 60.0, "round_limit_s": 600.0}
    with transport_time_limit(argparse.Namespace(transport="zenoh", team_timeout=None,
                                                 round_timeout="400")):
        assert launcher._within["time_limit"] == launcher.TEAM_TIMEOUT_S  # not touched
        assert options() == {"round_timeout_s": 400.0, "start_timeout_s": 800.0,
                             "round_limit_s": 800.0}
        # a caller's own options win, key by key (tests, bench: a team made on purpose)
        assert options(round_timeout_s=1.0) == {"round_timeout_s": 1.0,
                                                "start_timeout_s": 800.0, "round_limit_s": 800.0}
    assert options() == default
    with transport_time_limit(argparse.Namespace(transport="zenoh", team_timeout="420",
                                                 round_timeout="45")):
        assert launcher._within["time_limit"] == 420.0 and options()["start_timeout_s"] == 90.0
    assert launcher._within["time_limit"] == 600.0 and options() == default


@pytest.mark.parametrize("team, given", [("42", ""), (None, ", its default")])
@pytest.mark.parametrize("command", sorted(ARGS))
def test_a_round_timeout_not_below_the_team_limit_is_refused(command, team, given, capsys,
                                                             tmp_path, monkeypatch):
    """Every team would be stopped before a robot wrote a silent neighbour off: one line,
    exit 2, nothing written, the limit named (given, or the default 600 s)."""
    monkeypatch.chdir(tmp_path)
    limit = team or "600"
    more = ["--team-timeout", team] if team else []
    code = main([command, *ARGS[command], "--transport", "zenoh", *more,
                 "--round-timeout", limit])
    assert code == 2
    assert capsys.readouterr().err == (
        f"error: --round-timeout {limit} is not shorter than --team-timeout {limit}{given}: "
        "every team would be stopped before a robot wrote a silent neighbour off; raise "
        "--team-timeout above it (or lower --round-timeout)\n")
    assert not list(tmp_path.iterdir())


def test_a_team_file_keeps_its_own_timeouts(tmp_path):
    """``robot`` and ``observe`` read their team from a file: the option never reaches it."""
    import json

    from pipeline.team import launcher
    from pipeline.team.teamfile import load_team

    team = launcher.make_team("t", [[0, 1]], {"kind": "links", "links": "l.csv",
                                              "features_per_camera": [1, 1]},
                              {"round_timeout_s": 7.0})
    path = tmp_path / "TEAM.json"
    path.write_text(json.dumps(team.to_json()))
    with launcher.team_round_timeout(45.0):
        loaded = load_team(path)
    assert (loaded.options["round_timeout_s"], loaded.options["start_timeout_s"]) == (7.0, 60.0)
