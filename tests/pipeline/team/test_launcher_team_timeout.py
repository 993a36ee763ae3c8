"""A team of robot processes that does not end within ``--team-timeout`` is stopped, and the
error names the option (pipeline.team.launcher.launch_team, team_time_limit)."""

import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.__main__ import main

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture()
def links(tmp_path):
    p = tmp_path / "in.csv"
    p.write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,1,2,0\n")  # a conflict
    return p


def test_a_team_past_its_time_limit_stops_naming_the_option(links, tmp_path, capsys):
    t0 = time.monotonic()
    code = main(["resolve", "--links", str(links), "--out", str(tmp_path / "out.csv"),
                 "--transport", "zenoh", "--team-timeout", "0.2"])
    took = time.monotonic() - t0
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: the team of 3 robot processes did not end within 0.2 s (")
    assert err.rstrip().endswith("raise --team-timeout") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out.csv").exists()
    assert took < 15.0  # stopped, not left to the default 600 s


def test_the_same_team_ends_with_time_enough(links, tmp_path):
    out = subprocess.run([sys.executable, "-m", "pipeline", "resolve", "--links", str(links),
                          "--out", str(tmp_path / "out.csv"), "--transport", "zenoh",
                          "--team-timeout", "120"], cwd=ROOT, capture_output=True, text=True,
                         timeout=180)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "out.csv").is_file()


def test_each_team_of_an_online_run_gets_the_limit(tmp_path, capsys, monkeypatch):
    """An online run starts teams step after step: the limit reaches every one (here the
    first, the matching of step 0)."""
    from pipeline.team import launcher

    limits = []
    real = launcher.launch_team

    def spy(team, *a, **kw):
        limits.append(kw.get("timeout_s", launcher._within["time_limit"]))
        return real(team, *a, **kw)

    monkeypatch.setattr("pipeline.runs.transports.zenoh.launch_team", spy)
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    code = main(["run-formation", "--steps", "2", "--robots", "2", "--graph", "line",
                 "--size", "160x120", "--max-features", "200", "--no-rerun", "--transport",
                 "zenoh", "--team-timeout", "0.3", "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2
    assert "did not end within 0.3 s" in err and "raise --team-timeout" in err
    assert limits == [0.3]
