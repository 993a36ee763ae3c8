"""``launch_team(..., kill=(robot, status, delay_s, stop_s))``: fault injection of a robot
process FROZEN (``kill -STOP``, ``kill -CONT`` ``stop_s`` seconds later: a host suspended or
cut off for a while), not killed. Its process does not end: its neighbours write it off after
their round timeout, and the team ends once it resumed and published too."""

from zygote_teams import EDGES, FPC, LINKS

from pipeline.inputs.linkscsv import read_links_csv
from pipeline.team.assemble import consistency_of_team
from pipeline.team.launcher import launch_team, make_team


def test_a_robot_frozen_past_the_round_timeout_is_written_off_by_its_neighbours(tmp_path):
    links = tmp_path / "in.csv"
    links.write_text(LINKS)
    team = make_team("frozen", EDGES, {"kind": "links", "links": str(links),
                                       "features_per_camera": FPC},
                     {"round_timeout_s": 2.0}, n=4)
    run = launch_team(team, tmp_path / "w", kill=(2, "consistency", 0.0, 6.0),
                      stop_at_loss=True, timeout_s=120)
    assert 2 in run.frozen and run.killed == {} and run.stopped_at is None
    assert sorted(run.results) == [0, 1, 2, 3]  # it resumed and published, after the others
    res = consistency_of_team(team, run.results, read_links_csv(links).links, FPC, run.killed)
    assert 2 in res.stats["faults"]["robots_lost"]
    assert sorted(res.stats["faults"]["robots_lost"][2]) == [0, 1, 3]
