"""FORMATION_MATCH_ZYGOTE (pipeline.runs.transports.zenoh.ZYGOTE_ENV): an online run's teams
share one zygote by default (``run``) or each have their own (``team``); any other value is
refused by name before a team starts."""

import pytest

from pipeline.errors import InputError
from pipeline.runs.transports import zenoh
from pipeline.team import launcher


@pytest.mark.parametrize(("value", "shared"), [(None, True), ("run", True), ("", True),
                                               ("team", False)])
def test_the_online_robots_block_shares_a_zygote_unless_told(value, shared, monkeypatch):
    if value is None:
        monkeypatch.delenv(zenoh.ZYGOTE_ENV, raising=False)
    else:
        monkeypatch.setenv(zenoh.ZYGOTE_ENV, value)
    with zenoh.online_robots():
        inside = launcher._within["zygote"]
    assert (inside is not None) is shared
    assert launcher._within["zygote"] is None


def test_another_value_is_refused_by_name(monkeypatch):
    monkeypatch.setenv(zenoh.ZYGOTE_ENV, "shared")
    with pytest.raises(InputError, match=r"FORMATION_MATCH_ZYGOTE='shared': choose one of run, team"):
        with zenoh.online_robots():
            pass


@pytest.mark.parametrize(("transport", "value", "shared"),
                         [("zenoh", None, True), ("zenoh", "team", False), ("sim", None, False)])
def test_a_commands_teams_share_a_zygote_over_zenoh(transport, value, shared, monkeypatch):
    """The context a command with ``--transport`` runs in (``run-formations`` starts a team
    per formation) holds the zygote its teams share."""
    import argparse

    from pipeline.commands.options import transport_time_limit

    if value is None:
        monkeypatch.delenv(zenoh.ZYGOTE_ENV, raising=False)
    else:
        monkeypatch.setenv(zenoh.ZYGOTE_ENV, value)
    args = argparse.Namespace(transport=transport, team_timeout=None, round_timeout=None)
    with transport_time_limit(args):
        inside = launcher._within["zygote"]
    assert (inside is not None) is shared
    assert launcher._within["zygote"] is None


def test_a_bad_value_is_one_line_before_the_command_runs(monkeypatch, capsys, tmp_path):
    from pipeline.__main__ import main

    monkeypatch.setenv(zenoh.ZYGOTE_ENV, "per-team")
    links = tmp_path / "in.csv"
    links.write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n")
    code = main(["resolve", "--links", str(links), "--out", str(tmp_path / "out.csv"),
                 "--transport", "zenoh"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: FORMATION_MATCH_ZYGOTE='per-team': choose one")
    assert not (tmp_path / "out.csv").exists()
