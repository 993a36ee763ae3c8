"""A robot process frozen for good (``kill -STOP``, never resumed: a host suspended or cut off
for good). Its neighbours write it off after their round timeout and publish; the launcher
then gave it no end and held the team until its time limit (``--team-timeout``, minutes by
default), then failed. It now waits for it a grace of three times the team's round timeout once
every other robot has published, then kills it and counts it lost."""

import time

import pytest
from zygote_teams import EDGES, FPC, LINKS

from pipeline.inputs.linkscsv import read_links_csv
from pipeline.team.assemble import consistency_of_team
from pipeline.team.launcher import launch_team, lost_robots, make_team

ROUND_TIMEOUT_S = 2.0
FOR_GOOD_S = 3600.0  # far past anything the test waits for: the robot is never resumed
LIMIT_S = 60.0       # the team's time limit: the test fails there without the grace


def _team(tmp_path, name):
    links = tmp_path / "in.csv"
    links.write_text(LINKS)
    data = {"kind": "links", "links": str(links), "features_per_camera": FPC}
    return make_team(name, EDGES, data, {"round_timeout_s": ROUND_TIMEOUT_S}, n=4), links


def test_the_grace_is_three_times_the_longest_round_timeout(tmp_path):
    from pipeline.team.launcher import silent_grace_s

    team, _ = _team(tmp_path, "grace")
    assert silent_grace_s(team) == 3 * ROUND_TIMEOUT_S
    team.robot_options[3] = {"round_timeout_s": 7.0}  # one robot waits longer
    assert silent_grace_s(team) == 21.0


@pytest.mark.parametrize("stop_at_loss", [True, False])
def test_a_robot_frozen_for_good_is_killed_and_counted_lost(tmp_path, stop_at_loss):
    team, links = _team(tmp_path, "frozen-for-good")
    t0 = time.monotonic()
    run = launch_team(team, tmp_path / "w", kill=(2, "consistency", 0.0, FOR_GOOD_S),
                      stop_at_loss=stop_at_loss, timeout_s=LIMIT_S)
    took = time.monotonic() - t0
    assert 2 in run.frozen and 2 in run.silenced and run.killed == {}
    assert sorted(run.results) == [0, 1, 3]
    # its neighbours' results name it lost, and so does the launcher
    res = consistency_of_team(team, run.results, read_links_csv(links).links, FPC, run.killed)
    assert sorted(res.stats["faults"]["robots_lost"][2]) == [0, 1, 3]
    assert lost_robots(run, res.stats["faults"]["robots_lost"]) == [2]
    assert lost_robots(run) == [2]
    # killed one grace after the last of the others published, not at the time limit
    last = max(run.finished_at.values())
    assert run.silenced[2] - last >= 3 * ROUND_TIMEOUT_S
    assert took < LIMIT_S / 2


def test_a_batch_formation_run_ends_without_the_robot_frozen_for_good(tmp_path, monkeypatch):
    import json

    from pipeline.consistency.centralized import is_conflict_free
    from pipeline.runs.formation import FormationConfig, run_formation
    from pipeline.team.launcher import team_time_limit
    from pipeline.types import Links

    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    runs = []
    cfg = FormationConfig(formation="complete", robots=4, graph="complete", seed=0,
                          size=(160, 120), fusion=False, rerun=False, out=str(tmp_path / "run"))
    with team_time_limit(LIMIT_S):
        out = run_formation(cfg, transport="zenoh", kill=(2, "consistency", 0.0, FOR_GOOD_S),
                            keep_run=runs, round_timeout_s=ROUND_TIMEOUT_S)
    assert 2 in runs[0].silenced and sorted(runs[0].results) == [0, 1, 3]
    report = json.loads((out / "report.json").read_text())
    assert report["team"]["robots"]["2"]["silenced"] is True
    assert report["team"]["robots"]["2"]["result"] is None
    assert not any(r.get("silenced") for k, r in report["team"]["robots"].items() if k != "2")
    assert report["faults"]["robots_lost"] == {"2": [0, 1, 3]}
    rows = [r.split(",") for r in (out / "links.csv").read_text().splitlines()[1:]]
    assert not any(r[4] == "kept" and "2" in (r[0], r[2]) for r in rows)
    kept = [r for r in rows if r[4] == "kept"]
    kept = Links(*([int(r[c]) for r in kept] for c in range(4)))
    assert is_conflict_free(report["features_per_camera"], kept)


def test_a_process_computing_uses_cpu_time_and_a_frozen_one_none():
    """What tells a robot still computing (not silent) from a frozen one."""
    import signal
    import subprocess
    import sys

    from pipeline.team.launcher import _cpu_ticks

    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        a = _cpu_ticks(busy.pid)
        time.sleep(1.0)
        b = _cpu_ticks(busy.pid)
        assert a is not None and b > a
        busy.send_signal(signal.SIGSTOP)
        time.sleep(0.2)
        c = _cpu_ticks(busy.pid)
        time.sleep(1.0)
        assert _cpu_ticks(busy.pid) == c
    finally:
        busy.kill()
        busy.wait()
    assert _cpu_ticks(busy.pid) is None  # reaped: nothing to read
