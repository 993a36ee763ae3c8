"""The faults of a team run as its assembly reads them from the robots (pipeline.team.assemble):
the loss its robots injected, a robot lost in fusion."""


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


def test_a_landmark_whose_links_a_robot_lost_in_fusion_took_away_is_not_evaluated():
    """Robots 0 and 2 fused the track (0,0)-(1,0)-(2,0), then cut both links robot-lost when
    robot 1 died in fusion: no kept link holds the landmark, so it gets no track id (the
    observer's evaluation indexed the kept tracks with -1 and failed on IndexError)."""
    import numpy as np

    from pipeline.team.assemble import fusion_of_team
    from pipeline.team.launcher import make_team
    from pipeline.types import LinkLedger, Links

    team = make_team("lost-in-fusion", [[0, 1], [1, 2]],
                     {"kind": "links", "links": "x.csv", "features_per_camera": [1, 1, 1]}, n=3)
    ledger = LinkLedger.all_kept(Links([0, 1], [0, 0], [1, 2], [0, 0]))
    ledger.cut(np.array([True, True]), "robot-lost", 5)
    one = {"fusion_names": [0], "fusion_valid": [1], "fusion_estimated": [1],
           "fusion_inlier": [1], "fusion_theta": [[0.0, 0.0, 1.0]], "fusion_winner": [0],
           "fusion_feat": [0], "fusion_labels": [0], "link_s": [0], "link_r": [0],
           "fusion_cut": [0]}
    head = {"counters": {"messages_by_kind": {}, "bytes_by_kind": {}},
            "fusion": {"fusion_rounds": 1, "hypotheses": 1, "consensus": "exact",
                       "estimated": 1, "outliers": 0, "rounds": 1, "lost": [1]}}
    results = {i: (head, {**{k: np.asarray(v) for k, v in one.items()},
                          "link_nbr": np.asarray([1])}) for i in (0, 2)}
    stats, pts, ids, groups = fusion_of_team(team, results, ledger, [1, 1, 1])
    assert stats["tracks_fused"] == 1
    assert len(pts) == len(ids) == len(groups) == 0
