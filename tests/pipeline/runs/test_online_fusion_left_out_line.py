"""The line an online step prints when a frame's fusion robot was lost twice says the frame
was left out of the step's fusion: it said only 'lost and started again', as if the fusion
had run with it."""

import io

import pipeline.runs.transports.sim as sim
from pipeline.errors import RobotsLost
from pipeline.progress import StageTimer
from pipeline.runs.online import associate_online


def test_a_frame_left_out_of_the_fusion_is_said_so(monkeypatch):
    from data_synth.motion import render_motion

    fuse = sim.online_fusion
    calls = []

    def losing(views, *a, **kw):  # the fusion team's robot 0 lost twice
        calls.append(1)
        if len(calls) <= 2:
            raise RobotsLost("robot 0 of the fusion team did not publish a result", [0])
        return fuse(views, *a, **kw)

    monkeypatch.setattr(sim, "online_fusion", losing, raising=False)
    seq = render_motion("a", 0, 1, (160, 120), window=2)
    out = io.StringIO()
    run = associate_online(seq.flat.views, seq.n_robots, seq.step_edges, 2, "evidence",
                           StageTimer(stream=out), max_features=120, fusion=True)
    fusion = run.steps[0]["fusion"]
    assert fusion["frames_lost"] == [[0], [0]] and fusion["frames_left_out"] == [0]
    line = next(t for t in out.getvalue().splitlines() if "step 0:" in t)
    assert "frame(s) 0 left out of the step's fusion, lost twice" in line
