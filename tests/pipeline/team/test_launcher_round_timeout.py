"""``--round-timeout S`` reaches every team of robot processes a command starts: the TEAM.json
the launcher writes carries ``round_timeout_s`` S, and ``start_timeout_s`` and
``round_limit_s`` of pipeline.team.teamfile.round_timeout_options (pipeline.team.launcher.
make_team, team_round_timeout)."""

import json

import pytest

from pipeline.__main__ import main

TIMEOUTS = ("round_timeout_s", "start_timeout_s", "round_limit_s")


@pytest.fixture()
def written(monkeypatch):
    """The options of every TEAM.json the launcher writes, in order."""
    from pipeline.team import launcher

    teams = []
    real = launcher.write_team

    def spy(path, team):
        out = real(path, team)
        doc = json.loads(out.read_text())
        teams.append((doc["name"], {k: doc["options"][k] for k in TIMEOUTS}))
        return out

    monkeypatch.setattr(launcher, "write_team", spy)
    return teams


@pytest.fixture()
def links(tmp_path):
    p = tmp_path / "in.csv"
    p.write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,1,2,0\n")  # a conflict
    return p


def test_resolve_gives_its_team_the_round_timeout(links, tmp_path, written, capsys):
    code = main(["resolve", "--links", str(links), "--out", str(tmp_path / "out.csv"),
                 "--transport", "zenoh", "--round-timeout", "45"])
    assert code == 0, capsys.readouterr().err
    assert written == [("resolve", {"round_timeout_s": 45.0, "start_timeout_s": 90.0,
                                    "round_limit_s": 600.0})]
    assert (tmp_path / "out.csv").is_file()


def test_without_the_option_a_team_keeps_the_defaults(links, tmp_path, written, capsys):
    """(stopped by --team-timeout at once: only the TEAM.json it wrote matters here)"""
    code = main(["resolve", "--links", str(links), "--out", str(tmp_path / "out.csv"),
                 "--transport", "zenoh", "--team-timeout", "0.2"])
    assert code == 2 and "did not end within 0.2 s" in capsys.readouterr().err
    assert written == [("resolve", {"round_timeout_s": 30.0, "start_timeout_s": 60.0,
                                    "round_limit_s": 600.0})]


def test_each_team_of_an_online_run_gets_the_round_timeout(tmp_path, written, capsys,
                                                           monkeypatch):
    """An online run makes teams step after step, each step's matching, the rule's stage
    and fusion: each carries the option."""
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    code = main(["run-formation", "--steps", "2", "--robots", "2", "--graph", "line",
                 "--size", "160x120", "--max-features", "200", "--no-rerun", "--transport",
                 "zenoh", "--round-timeout", "300", "--out", str(tmp_path / "run")])
    assert code in (0, 3), capsys.readouterr().err
    names = [name for name, _ in written]
    assert {"online-match-0", "online-match-1", "resolve", "online-fusion"} <= set(names), names
    want = {"round_timeout_s": 300.0, "start_timeout_s": 600.0, "round_limit_s": 600.0}
    assert all(options == want for _, options in written), written
