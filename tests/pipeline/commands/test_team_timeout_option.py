"""``--team-timeout S`` (pipeline.commands.options): on every command that takes --transport,
checked like the other numeric options (one line, exit 2) before the command runs, refused
where the transport starts no team of processes."""

import pytest

from pipeline.__main__ import COMMANDS, build_parser, main
from pipeline.commands.options import team_timeout, transport_time_limit
from pipeline.errors import InputError

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


@pytest.mark.parametrize("command", sorted(ARGS))
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "0", "-5", "1e9", "ten", ""])
def test_a_bad_team_timeout_is_one_line_and_exit_2(command, value, capsys, tmp_path,
                                                   monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing is written: the option is checked first
    code = main([command, *ARGS[command], "--transport", "zenoh", f"--team-timeout={value}"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"error: --team-timeout {value!r}: ")
    assert "e.g. --team-timeout 1800" in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("command", sorted(ARGS))
def test_team_timeout_is_refused_on_the_simulator(command, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for transport in ([], ["--transport", "sim"]):
        assert main([command, *ARGS[command], *transport, "--team-timeout", "60"]) == 2
        err = capsys.readouterr().err
        assert err == ("error: --team-timeout applies to robot processes (--transport zenoh); "
                       "--transport sim starts none: drop it, or add --transport zenoh\n")


@pytest.mark.parametrize("text, seconds", [("1800", 1800.0), ("0.5", 0.5), ("1e3", 1000.0)])
def test_team_timeout_reads_seconds(text, seconds):
    assert team_timeout(text) == seconds


def test_the_limit_reaches_launch_team_and_is_restored():
    import argparse

    from pipeline.team import launcher

    args = argparse.Namespace(transport="zenoh", team_timeout="42")
    assert launcher._time_limit["s"] == launcher.TEAM_TIMEOUT_S == 600.0
    with transport_time_limit(args):
        assert launcher._time_limit["s"] == 42.0
    assert launcher._time_limit["s"] == 600.0
    with transport_time_limit(argparse.Namespace(transport="zenoh", team_timeout=None)):
        assert launcher._time_limit["s"] == 600.0
    with pytest.raises(InputError, match="applies to robot processes"):
        transport_time_limit(argparse.Namespace(transport="sim", team_timeout="42"))
