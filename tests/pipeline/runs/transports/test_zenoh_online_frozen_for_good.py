"""An online step over Zenoh whose robot process is FROZEN FOR GOOD (``kill -STOP``, never
resumed: a host suspended or cut off for good). Its neighbours write it off and publish;
the launcher held the team until its time limit and the run stopped with "the team of N
robot processes did not end within S s". The launcher now kills it a grace after the others
published (:func:`pipeline.team.launcher.silent_grace_s`), and the step goes on as with a
killed robot: started again, and a frame lost twice has its links of the step cut
``robot-lost``."""

import numpy as np
from frozen_robots import freezing

import pipeline.runs.transports.zenoh as zenoh
from pipeline.runs.online import associate_online
from pipeline.team.launcher import team_round_timeout, team_time_limit

ROUND_TIMEOUT_S = 2.0
FOR_GOOD_S = 3600.0  # never resumed within the test
LIMIT_S = 60.0       # each team's time limit: without the grace the step stops there


def test_a_stage_robot_frozen_for_good_twice_has_its_frames_links_of_the_step_cut(
        monkeypatch):
    from data_synth.motion import render_motion
    from pipeline.progress import StageTimer

    monkeypatch.setattr(zenoh, "online_stage",
                        freezing(zenoh.online_stage, {0, 1}, 1, FOR_GOOD_S))
    seq = render_motion("a", 0, 1, (160, 120), window=2)
    with team_round_timeout(ROUND_TIMEOUT_S), team_time_limit(LIMIT_S):
        run = associate_online(seq.flat.views, seq.n_robots, seq.step_edges, 2, "evidence",
                               StageTimer(verbose=False), max_features=120, fusion=False,
                               transport="zenoh")
    oa = run.online
    rec = run.steps[0]
    lost = rec["images_lost"]
    assert rec["stage_attempts"] == 3 and len(lost) == 2 and lost[0] == lost[1]
    assert rec["cut_lost"] > 0 and rec["conflictive_sets_after"] == 0
    g = lost[0][0]
    L = oa.links
    cut = np.flatnonzero(L.reason == "robot-lost")
    assert len(cut) == rec["cut_lost"]
    assert np.all((L.ci[cut] == g) | (L.cj[cut] == g)) and not L.kept[cut].any()
