"""``launch_team(..., kill=(robot, status, delay_s, stop_s))``: fault injection of a robot
process FROZEN (``kill -STOP``, ``kill -CONT`` ``stop_s`` seconds later: a host suspended or
cut off for a while), not killed. Its process does not end: its neighbours write it off after
their round timeout, and the team ends once it resumed and published too."""

from zygote_teams import FPC, links_team

from pipeline.inputs.linkscsv import read_links_csv
from pipeline.team.assemble import consistency_of_team
from pipeline.team.launcher import launch_team


def test_a_robot_frozen_past_the_round_timeout_is_written_off_by_its_neighbours(tmp_path):
    team, links = links_team(tmp_path, "frozen", {"round_timeout_s": 2.0})
    run = launch_team(team, tmp_path / "w", kill=(2, "consistency", 0.0, 6.0),
                      stop_at_loss=True, timeout_s=120)
    assert 2 in run.frozen and run.killed == {} and run.stopped_by == []
    assert sorted(run.results) == [0, 1, 2, 3]  # it resumed and published, after the others
    res = consistency_of_team(team, run.results, read_links_csv(links).links, FPC, run.killed)
    assert 2 in res.stats["faults"]["robots_lost"]
    assert sorted(res.stats["faults"]["robots_lost"][2]) == [0, 1, 3]


def test_written_off_names_the_frozen_robot_not_the_neighbours_it_wrote_off_later():
    from pipeline.team.launcher import TeamRun, written_off

    run = TeamRun(team=None, finished_at={0: 5.0, 2: 6.0, 1: 17.0})
    # robot 1 frozen: 0 and 2 wrote it off and ended; resumed, it wrote them off in turn
    assert written_off(run, {1: [0, 2], 0: [1], 2: [1]}) == [1]
    # a robot named by one that was not itself named stays lost, published or not
    assert written_off(run, {0: [1]}) == [0]
    assert written_off(TeamRun(team=None, finished_at={0: 5.0}), {1: [0]}) == [1]
    # named by each other (a link cut both ways): the one that published last is lost
    assert written_off(run, {0: [2], 2: [0]}) == [2]
    assert written_off(run, {}) == []


def test_a_robot_that_ended_before_its_injected_kill_is_not_killed(tmp_path):
    # the kill comes 10 s after the robot's consistency status: the team of four ends within
    # a second or two, and the robot's pid was reaped ('error: No such process' ended the
    # command, or a process that took the pid since would have been killed)
    team, links = links_team(tmp_path, "ended")
    run = launch_team(team, tmp_path / "w", kill=(1, "consistency", 10.0), stop_at_loss=True,
                      timeout_s=120)
    assert run.stopped_by == [] and sorted(run.results) == [0, 1, 2, 3]
    assert run.killed == {}
