"""The faults section of a team run names the loss its robots injected, a robot's own option
included (pipeline.team.assemble)."""


def test_loss_set_by_one_robots_option_is_the_teams_drop_probability(tmp_path):
    from pipeline.runs.transports.zenoh import links_of_run, write_robot_links
    from pipeline.team.launcher import launch_team, make_team
    from pipeline.types import Links

    links = Links([0, 0, 1, 2], [0, 1, 0, 0], [1, 3, 2, 3], [0, 0, 1, 1], [0.9, 0.2, 0.8, 0.7])
    paths = [str(p) for p in write_robot_links(tmp_path, links, 4)]
    team = make_team("lossy-two", [[0, 1], [1, 2], [2, 3], [0, 3]],
                     {"kind": "links", "links": paths, "features_per_camera": [2, 2, 2, 2]},
                     {"resolution": "evidence"}, n=4)
    team.robot_options = {2: {"drop_prob": 0.3}}
    run = launch_team(team, tmp_path / "work")
    assert sorted(run.results) == [0, 1, 2, 3]
    faults = links_of_run(team, run).stats["faults"]
    assert faults["drop_probability"] == 0.3
