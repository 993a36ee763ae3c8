"""bench/online_team.py's ``zenoh, hosts in namespaces, 1mbit cables``: the online run with every
robot on a host of its own (FORMATION_MATCH_HOSTS=netns:1mbit) printed beside the other
configurations, or left out with the reason where namespaces cannot be made; the other
configurations run on the loopback whatever the caller's environment says."""

import json
import subprocess

import pytest
from benchload import load_bench

import pipeline.team.netns as netns

HOSTS = "zenoh, hosts in namespaces, 1mbit cables"


def _fake_runs(bench, monkeypatch, steps: int) -> list:
    """Replace the bench's command-line runs by rows of made-up figures; the calls made."""
    calls = []

    def run(args, out, env=None, kill_step=None, lost_step=None):
        calls.append((list(args), env))
        return {"wall_s": 10.0 + len(calls), "online_s": 5.0, "fusion_s": 2.0,
                "stage_s": [1.0] * steps, "match_s": [0.5] * steps, "match_bytes": 1000,
                "fusion_cut": [0] * steps, "fusion_tracks": [3] * steps,
                "fusion_bytes": 2000, "naming_bytes": 500, "links": 7,
                "match_attempts": [1] * steps, "stage_attempts": [1] * steps,
                "fusion_frames_lost": [0] * steps, "tables": ["links", "steps"],
                "frames_void": [[]] + [[k * 6] for k in range(1, steps)]
                if lost_step is not None else [[]] * steps, "f1": 0.8}

    monkeypatch.setattr(bench, "_run", run)
    return calls


def test_the_configuration_runs_on_hosts_and_prints_its_row(monkeypatch, capsys, tmp_path):
    bench = load_bench("online_team")
    monkeypatch.setattr(netns, "unavailable", lambda: None)
    calls = _fake_runs(bench, monkeypatch, 2)
    assert bench.main(["--formation", "a", "--steps", "2", "--out", str(tmp_path)]) == 0
    assert [env for args, env in calls if env and "FORMATION_MATCH_HOSTS" in env] == \
        [{"FORMATION_MATCH_HOSTS": "netns:1mbit"}]
    assert len(calls) == len(bench.CONFIGS) == 8
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith(HOSTS)]
    assert len(rows) == 3  # its figures, its steps, its comparison with zenoh
    assert rows[0].split()[-1] == "True"
    assert f"{HOSTS}: the same tables as the simulator: True" in out
    runs = json.loads((tmp_path / "results.json").read_text())["runs"]
    assert runs[HOSTS]["tables_equal_sim"] is True


def test_without_namespaces_it_is_left_out_with_the_reason(monkeypatch, capsys, tmp_path):
    bench = load_bench("online_team")
    monkeypatch.setattr(netns, "unavailable", lambda: "making network namespaces needs root")
    calls = _fake_runs(bench, monkeypatch, 2)
    assert bench.main(["--formation", "a", "--steps", "2", "--out", str(tmp_path)]) == 0
    assert all(env is None or "FORMATION_MATCH_HOSTS" not in env for _, env in calls)
    assert len(calls) == 7
    out = capsys.readouterr().out
    assert out.count(HOSTS) == 1
    assert f"{HOSTS}: left out, no network namespaces here (making network namespaces needs " \
           "root)" in out
    assert HOSTS not in json.loads((tmp_path / "results.json").read_text())["runs"]


@pytest.mark.parametrize("config, hosts", [("zenoh", "loopback"), (HOSTS, "netns:1mbit")])
def test_the_callers_setting_does_not_reach_the_other_configurations(monkeypatch, tmp_path,
                                                                     config, hosts):
    """FORMATION_MATCH_HOSTS exported in the caller's shell: only the hosts configuration
    runs on hosts of their own."""
    bench = load_bench("online_team")
    monkeypatch.setenv("FORMATION_MATCH_HOSTS", "netns:256kbit")
    seen = []

    def run(argv, **kw):
        seen.append(kw["env"])
        return subprocess.CompletedProcess(argv, 1, b"", b"stopped here")

    monkeypatch.setattr(bench.subprocess, "run", run)
    with pytest.raises(RuntimeError, match="stopped here"):
        bench._run(bench.CONFIGS[config], tmp_path / "out", bench.ENV.get(config))
    assert seen[0]["FORMATION_MATCH_HOSTS"] == hosts


def test_the_robot_lost_for_good_row_names_its_void_frames(monkeypatch, capsys, tmp_path):
    """``zenoh, robot 0 lost for good``: the one run with ``lost_step`` = ``--kill-step``
    (never with ``kill_step``); its void frames, F1 and matching time printed."""
    bench = load_bench("online_team")
    monkeypatch.setattr(netns, "unavailable", lambda: "no")
    _fake_runs(bench, monkeypatch, 3)
    run, steps = bench._run, []

    def spy(args, out, env=None, kill_step=None, lost_step=None):
        steps.append((kill_step, lost_step))
        return run(args, out, env, kill_step, lost_step)

    monkeypatch.setattr(bench, "_run", spy)
    assert bench.main(["--formation", "a", "--steps", "3", "--out", str(tmp_path)]) == 0
    assert sorted(steps, key=str) == sorted([(None, None)] * 5 + [(1, None), (None, 1)], key=str)
    out = capsys.readouterr().out
    assert "zenoh, robot 0 lost for good from step 1: frames void per step [[], [6], [12]]" in out
