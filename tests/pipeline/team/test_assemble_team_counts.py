"""A team run's per-phase records carry the team's counts, as the simulator's do, not those
of the one robot whose phase log they are read from."""


def test_a_detection_record_counts_every_robots_conflictive_features(tmp_path):
    import numpy as np

    from pipeline.consistency import resolve_conflicts
    from pipeline.runs.transports.zenoh import links_of_run, write_robot_links
    from pipeline.team.launcher import launch_team, make_team
    from pipeline.types import Links

    # the paper's Fig. 1: the chain 0:0 - 1:0 - 2:0 - 3:0 - 0:1 joins two features of camera 0
    m = [2, 1, 1, 1]
    edges = [[0, 1], [1, 2], [2, 3], [0, 3]]
    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    sim = resolve_conflicts(np.array(m), np.array(edges), links, resolution="paper")
    paths = [str(p) for p in write_robot_links(tmp_path, links, 4)]
    team = make_team("fig1", edges, {"kind": "links", "links": paths, "features_per_camera": m},
                     {"resolution": "paper"}, n=4)
    res = links_of_run(team, launch_team(team, tmp_path / "work"))
    def cut(r):  # the cut links, whatever the order the result lists them in
        L = r.links
        return sorted(zip(L.cam_i[r.deleted].tolist(), L.feat_i[r.deleted].tolist(),
                          L.cam_j[r.deleted].tolist(), L.feat_j[r.deleted].tolist(), strict=True))

    assert cut(res) == cut(sim) == [(2, 0, 3, 0)]
    first_sim = sim.stats["per_iteration"][0]
    detection = [p for p in res.stats["per_iteration"] if p.get("phase") == "detection"]
    resolution = [p for p in res.stats["per_iteration"] if p.get("phase") == "resolution"]
    assert first_sim["conflictive_features"] == 5
    assert detection[0]["conflictive_features"] == first_sim["conflictive_features"]
    assert resolution[0]["conflictive_sets"] == first_sim["conflictive_sets"] == 1
    assert detection[-1]["conflictive_features"] == 0
