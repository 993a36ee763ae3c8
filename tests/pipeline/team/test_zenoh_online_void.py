"""An online run over Zenoh whose step matching loses one robot twice (its team and the
team started again): the mission goes on without that robot's new frame (void: no
features, no links), and the robot takes part again at the next step."""

import csv
import json
from pathlib import Path

import pipeline.runs.transports.zenoh as zenoh
from pipeline.__main__ import main

ARGS = ["run-formation", "--steps", "3", "--window", "2", "--size", "160x120",
        "--max-features", "120", "--no-rerun", "--resolution", "evidence", "--no-fusion"]
#: four robots on a ring (robot 0 talks to 1 and 3)
RING = ["--robots", "4", "--graph", "ring"]


def _made(folder: Path) -> dict:
    """step -> the links made at that step, as (cam_i, feat_i, cam_j, feat_j)."""
    with open(folder / "links.csv") as f:
        links = [tuple(int(r[k]) for k in ("cam_i", "feat_i", "cam_j", "feat_j"))
                 for r in csv.DictReader(f)]
    out: dict = {}
    with open(folder / "link_steps.csv") as f:
        for r in csv.DictReader(f):
            out.setdefault(int(r["step_added"]), set()).add(links[int(r["link"])])
    return out


def test_a_robot_lost_twice_by_a_step_matching_leaves_its_frame_void(tmp_path, monkeypatch):
    assert main([*ARGS, *RING, "--out", str(tmp_path / "sim")]) == 0
    job, calls = zenoh.online_match, []

    def killing(*args, **kw):  # robot 0 of step 1's matching, in both teams
        calls.append(1)
        if len(calls) == 2:
            kw["kill"] = [(0, "started", 0.0), (0, "started", 0.0)]
        return job(*args, **kw)

    monkeypatch.setattr(zenoh, "online_match", killing)
    assert main([*ARGS, *RING, "--transport", "zenoh", "--round-timeout", "5",
                 "--out", str(tmp_path / "zen")]) == 0
    rep = json.loads((tmp_path / "zen" / "report.json").read_text())
    steps = rep["steps"]
    with open(tmp_path / "zen" / "images.csv") as f:
        n = sum(1 for r in csv.DictReader(f) if r["step"] == "0")
    void = n  # robot 0's frame of step 1
    assert [s["match_attempts"] for s in steps] == [1, 2, 1]
    assert steps[1]["match_robots_lost"] == [[0], [0]]
    assert [s["match_frames_void"] for s in steps] == [[], [void], []]
    assert steps[1]["match_pairs_unmatched"] > 0
    assert all(s["conflictive_sets_after"] == 0 for s in steps)
    assert rep["features_per_camera"][void] == 0
    assert [w["code"] for w in rep["warnings"]] == ["frames-void"]
    sim, zen = _made(tmp_path / "sim"), _made(tmp_path / "zen")
    assert zen[0] == sim[0]
    # step 1: every pair with a frame of robot 0 (its new frame, and its frame of step 0,
    # which it never sent) went unmatched; every other pair as the simulator matched it
    robot0 = {0, void}
    assert zen[1] == {e for e in sim[1] if e[0] not in robot0 and e[2] not in robot0}
    # step 2: robot 0 is back; only the pairs of the void frame are gone
    assert zen[2] == {e for e in sim[2] if void not in (e[0], e[2])}
    assert zen[2] != sim[2] and zen[1] != sim[1]


def test_a_robot_lost_for_good_leaves_every_later_frame_void(tmp_path, monkeypatch):
    """Robot 1 of a line 0 - 1 - 2 is gone for good from step 1 on (every matching team
    loses it): robots 0 and 2, whose only neighbour it was, match their own frames alone
    (they used to end with exit 3, "no neighbour answered", and stop the mission), each of
    robot 1's later frames is void, and the mission ends conflict-free after every step."""
    job = zenoh.online_match

    def killing(views, t, *args, **kw):
        if t >= 1:
            kw["kill"] = [(1, "started", 0.0), (1, "started", 0.0)]
        return job(views, t, *args, **kw)

    monkeypatch.setattr(zenoh, "online_match", killing)
    assert main([*ARGS, "--robots", "3", "--graph", "line", "--transport", "zenoh",
                 "--round-timeout", "5", "--out", str(tmp_path / "zen")]) == 0
    rep = json.loads((tmp_path / "zen" / "report.json").read_text())
    steps = rep["steps"]
    assert [s["match_frames_void"] for s in steps] == [[], [4], [7]]
    assert [s["match_attempts"] for s in steps] == [1, 2, 2]
    assert all(s["conflictive_sets_after"] == 0 for s in steps)
    with open(tmp_path / "zen" / "links.csv") as f:
        rows = list(csv.DictReader(f))
    ends = {int(r[k]) for r in rows for k in ("cam_i", "cam_j")}
    assert not ends & {4, 7}
    # robots 0 and 2 matched their new frames alone, against their own earlier ones and
    # (robot 0) robot 1's frame of step 0, which robot 1 had sent it then
    made = _made(tmp_path / "zen")
    assert {(e[0], e[2]) for e in made[1]} == {(0, 3), (1, 3), (2, 5)}
    assert {(e[0], e[2]) for e in made[2]} == {(3, 6), (5, 8)}
