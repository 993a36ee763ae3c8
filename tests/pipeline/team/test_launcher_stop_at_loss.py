"""``launch_team(..., stop_at_loss=True)``: a robot whose process ends without publishing
stops the team at once (the others killed, their results not waited for), for a caller that
starts the team again anyway (an online step); without it the survivors finish without the
lost robot, as a team without a launcher would."""


from zygote_teams import links_team

from pipeline.team.launcher import launch_team


def _team(tmp_path):
    # a neighbour written off after 20 s of silence: a stop at once is far below it
    return links_team(tmp_path, "stopped", {"round_timeout_s": 20.0})[0]


def test_a_robot_killed_at_its_start_stops_the_team(tmp_path):
    run = launch_team(_team(tmp_path), tmp_path / "a", kill=(2, "started", 0.0),
                      stop_at_loss=True, timeout_s=120)
    assert run.stopped_by == [2] and 2 in run.killed and 2 not in run.results


def test_without_it_the_survivors_finish_without_the_lost_robot(tmp_path):
    run = launch_team(_team(tmp_path), tmp_path / "b", kill=(2, "consistency", 0.0),
                      timeout_s=120)
    assert run.stopped_by == []
    assert sorted(run.results) == [0, 1, 3]
