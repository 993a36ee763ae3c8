"""A robot's record of the frames it sent (``sent.json``, pipeline.team.online_match) keeps
only frames still in the window, also for a neighbour it does not talk to at this step."""

import json

import numpy as np

from pipeline.matching.features import MERGE_RADIUS_PX
from pipeline.runs.transports.zenoh import team_options
from pipeline.team.launcher import make_team
from pipeline.team.online_match import online_match_main, write_frame
from pipeline.types import View


class _Alone:
    """A transport on which the robot talks to nobody at this step."""

    neighbours = frozenset()

    def send(self, dst, kind, payload):
        raise AssertionError("nothing to send")

    def end_round(self, state=None):
        return [], {}

    def counters(self):
        return {"messages": 0, "bytes": 0}


def test_frames_sent_to_a_neighbour_absent_now_are_forgotten_when_they_leave_the_window(
        tmp_path):
    """Robot 0 of 3, window 1, step 2: it sent frames 0 and 3 (steps 0 and 1) to robot 1 at
    earlier steps and does not talk to it now; both left the window, so the record drops
    them (it kept them, and every frame ever sent to a neighbour out of reach, for good)."""
    rng = np.random.default_rng(0)
    view = View(name="cam", image=rng.integers(0, 255, (60, 80), dtype=np.uint8),
                K=np.array([[60.0, 0, 40], [0, 60.0, 30], [0, 0, 1]]))
    camera = tmp_path / "camera-0.npz"
    write_frame(camera, view)
    store = tmp_path / "robot-0"
    store.mkdir()
    (store / "sent.json").write_text(json.dumps({"1": [0, 3], "2": [3]}))
    data = {"kind": "online-match", "step": 2, "window": 1, "frames": [str(camera)] * 3,
            "store": [str(tmp_path / f"robot-{i}") for i in range(3)]}
    team = make_team("online-match-2", [[0, 1], [1, 2]], data,
                     team_options("sift", 100, None, merge_radius=MERGE_RADIUS_PX), n=3)
    header, _ = online_match_main(team, 0, _Alone())
    assert header["frame"] == 6 and header["pairs"] == []
    assert json.loads((store / "sent.json").read_text()) == {}
    assert sorted(p.name for p in store.glob("frame-*.npz")) == ["frame-6.npz"]
