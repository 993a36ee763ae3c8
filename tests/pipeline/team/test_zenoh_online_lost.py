"""An online run over Zenoh that loses robot processes (``kill -9``) during a step's
matching, stage and fusion: the lost robot is started again with its team and the run ends
as the simulator's; a frame lost twice in one step has its links of that step cut
``robot-lost`` and the run still ends conflict-free after every step."""

import json
from pathlib import Path

import pipeline.runs.transports.zenoh as zenoh
from pipeline.__main__ import main

# four robots on a ring: a cycle (links to cut), each team's start-up half the six's
ARGS = ["run-formation", "--steps", "3", "--window", "2", "--size", "160x120",
        "--max-features", "120", "--robots", "4", "--graph", "ring", "--no-rerun",
        "--resolution", "evidence"]


def _killing(job, calls, status="consistency"):
    """``job`` (a transport's online job) that kills the team's robot 0 as soon as it
    publishes ``status``, on its calls numbered in ``calls`` (from 0)."""
    seen = []

    def wrapped(*args, **kw):
        seen.append(1)
        if len(seen) - 1 in calls:
            kw["kill"] = (0, status, 0.0)
        return job(*args, **kw)

    return wrapped, seen


def test_robots_lost_once_are_started_again_and_the_run_ends_as_the_simulators(
        tmp_path, monkeypatch):
    assert main([*ARGS, "--out", str(tmp_path / "sim")]) == 0
    stage, _ = _killing(zenoh.online_stage, {1})    # step 1's stage
    fusion, _ = _killing(zenoh.online_fusion, {2})  # step 2's fusion
    match, _ = _killing(zenoh.online_match, {1}, "started")  # step 1's matching
    monkeypatch.setattr(zenoh, "online_stage", stage)
    monkeypatch.setattr(zenoh, "online_fusion", fusion)
    monkeypatch.setattr(zenoh, "online_match", match)
    assert main([*ARGS, "--transport", "zenoh", "--round-timeout", "5",
                 "--out", str(tmp_path / "zen")]) == 0
    for name in ("links.csv", "link_steps.csv"):
        sim = Path(tmp_path / "sim" / name).read_text().splitlines()
        assert Path(tmp_path / "zen" / name).read_text().splitlines() == sim, name
    steps = json.loads((tmp_path / "zen" / "report.json").read_text())["steps"]
    assert [s["stage_attempts"] for s in steps] == [1, 2, 1]
    assert [s["match_attempts"] for s in steps] == [1, 2, 1]
    assert steps[1]["match_robots_lost"] == [[0]] and steps[0]["match_robots_lost"] == []
    assert len(steps[1]["images_lost"]) == 1 and steps[1]["cut_lost"] == 0
    assert [len(s["fusion"].get("frames_lost", [])) for s in steps] == [0, 0, 1]
    assert steps[2]["fusion"]["frames_left_out"] == []


def test_a_frame_lost_twice_in_a_step_has_its_links_of_the_step_cut(tmp_path, monkeypatch):
    stage, seen = _killing(zenoh.online_stage, {1, 2})  # step 1's stage, and again
    monkeypatch.setattr(zenoh, "online_stage", stage)
    assert main([*ARGS, "--transport", "zenoh", "--round-timeout", "5", "--no-fusion",
                 "--out", str(tmp_path / "zen")]) == 0
    rep = json.loads((tmp_path / "zen" / "report.json").read_text())
    steps = rep["steps"]
    lost = steps[1]["images_lost"]
    assert len(lost) == 2 and lost[0] == lost[1] and steps[1]["cut_lost"] > 0
    assert all(s["conflictive_sets_after"] == 0 for s in steps)
    g = lost[0][0]
    rows = [r.split(",") for r in (tmp_path / "zen" / "links.csv").read_text().splitlines()[1:]]
    cut = [r for r in rows if r[5] == "robot-lost"]
    assert len(cut) == steps[1]["cut_lost"]
    assert all(str(g) in (r[0], r[2]) and r[6] == "1" for r in cut)  # its links, at step 1
