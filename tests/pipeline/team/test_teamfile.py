import json

import pytest

from pipeline.errors import InputError
from pipeline.team.teamfile import load_team, parse_team

_LINKS = {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2, 2]}
_CAM = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "t": [0.0, 0.0, 1.5]}


def _doc(**over):
    doc = {"version": 1, "name": "t", "comm_edges": [[0, 1], [1, 2]],
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(3)],
           "data": {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2, 2]}}
    doc.update(over)
    return doc


def test_a_valid_team_parses():
    t = parse_team(_doc(options={"drop_prob": 0.1}, robot_options={"2": {"loss_timeout": 9}}))
    assert t.n == 3 and t.neighbours(1) == [0, 2] and t.neighbours(0) == [1]
    assert t.options_for(2)["loss_timeout"] == 9 and t.options_for(2)["drop_prob"] == 0.1
    assert parse_team(t.to_json()).to_json() == t.to_json()


@pytest.mark.parametrize("over, words", [
    ({"robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:1"}]}, "at least 2"),
    ({"robots": [{"id": 0, "endpoint": "tcp/h:1"}, {"id": 2, "endpoint": "tcp/h:2"}]},
     "id 1 is missing"),
    ({"robots": [{"id": 0, "endpoint": "tcp/h:1"}, {"id": 1, "endpoint": "tcp/h:1"}]},
     "share endpoint"),
    ({"robots": [{"id": 0, "endpoint": "h:1"}, {"id": 1, "endpoint": "tcp/h:2"}]},
     "tcp/HOST:PORT"),
    ({"robots": [{"id": 0, "endpoint": "tcp/h:99999"}, {"id": 1, "endpoint": "tcp/h:2"}]},
     "1..65535"),
    ({"comm_edges": [[0, 3]]}, "[0, 3]"),
    ({"comm_edges": "0-1"}, "comm_edges"),
    ({"data": {"kind": "video"}}, "kind"),
    ({"data": {"kind": "links", "links": "x", "features_per_camera": [1]}}, "3 counts"),
    ({"options": {"drop_prob": 1.5}}, "drop_prob"),
    ({"options": {"speed": 1}}, "unknown option 'speed'"),
    ({"colour": 1}, "unknown key 'colour'"),
    ({"robot_options": {"1": {"resolution": "paper"}}}, "'resolution', which is the team's"),
    ({"options": {"wire": "gzip"}}, "wire 'gzip' must be one of compact, plain"),
    ({"data": {"kind": "links", "links": ["a.csv", "b.csv"], "features_per_camera": [1, 1, 1]}},
     "a list of 3 paths, one per robot"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"]}},
     "data.keypoints is given without data.cameras"),
    ({"data": {**_LINKS, "cameras": [_CAM] * 3}}, "data.cameras is given without data.keypoints"),
    ({"data": {**_LINKS, "keypoints": ["k0"], "cameras": [_CAM] * 3}},
     "data.keypoints must list 3 paths"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"], "cameras": [_CAM] * 2}},
     "data.cameras must list 3 cameras"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"],
               "cameras": [_CAM, {**_CAM, "dist": [0]}, _CAM]}},
     "data.cameras[1] must be an object with exactly \"K\", \"R\" and \"t\"; unknown key 'dist'"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"],
               "cameras": [_CAM, _CAM, {**_CAM, "R": [[1, 0], [0, 1]]}]}},
     "data.cameras[2].R must be a 3x3 matrix"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"],
               "cameras": [{**_CAM, "t": [0, 0, "1"]}, _CAM, _CAM]}},
     "data.cameras[0].t [0, 0, '1'] must be 3 finite numbers"),
    ({"options": {"fusion": True}}, "options sets fusion on a links team without data.keypoints"),
    ({"robot_options": {"1": {"fusion": True}}},
     "robot_options['1'] sets fusion on a links team without data.keypoints"),
])
def test_malformed_team_is_one_line_error(over, words):
    with pytest.raises(InputError) as e:
        parse_team(_doc(**over))
    assert words in str(e.value) and "\n" not in str(e.value)


def test_robot_id_outside_the_team(tmp_path):
    p = tmp_path / "TEAM.json"
    p.write_text(json.dumps(_doc()))
    team = load_team(p)
    assert team.check_id("2") == 2
    for bad in ("3", "-1", "x", "1.0"):
        with pytest.raises(InputError, match="not a robot of team 't'; its robots are 0..2"):
            team.check_id(bad)


def test_missing_or_invalid_json_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_team(tmp_path / "nope.json")
    p = tmp_path / "TEAM.json"
    p.write_text("{robots: 1")
    with pytest.raises(InputError, match="not valid JSON"):
        load_team(p)


def test_the_launcher_refuses_an_edge_listed_twice():
    from pipeline.team.launcher import make_team

    data = {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1, 1]}
    with pytest.raises(InputError, match=r"comm edge \(0, 1\) is listed more than once"):
        make_team("t", [[0, 1], [1, 0], [1, 2]], data, n=3)


def test_writing_a_team_file_never_writes_through_a_name_beside_it(tmp_path):
    import os

    from pipeline.team.teamfile import write_team

    precious = tmp_path / "precious.txt"
    precious.write_text("precious")
    (tmp_path / f"TEAM.json.tmp{os.getpid()}").symlink_to(precious)
    write_team(tmp_path / "TEAM.json", parse_team(_doc()))
    assert precious.read_text() == "precious"
    assert load_team(tmp_path / "TEAM.json").n == 3


def test_each_robot_names_its_own_links_file(tmp_path):
    from pipeline.team.teamfile import check_data_files, links_file_of

    p = tmp_path / "TEAM.json"
    p.write_text(json.dumps(_doc(data={"kind": "links", "links": ["r0.csv", "r1.csv", "r2.csv"],
                                       "features_per_camera": [2, 2, 2]})))
    team = load_team(p)
    assert links_file_of(team, 1) == (tmp_path / "r1.csv", True)
    (tmp_path / "r1.csv").write_text("cam_i,feat_i,cam_j,feat_j\n0,1,1,0\n")
    # robot 1 needs only its own file: the others' may live on other machines
    assert [q for _, q in check_data_files(team, 1)] == [tmp_path / "r1.csv"]
    with pytest.raises(InputError, match=r"data.links\[0\]"):
        check_data_files(team, 0)


def test_a_links_team_with_keypoints_and_cameras(tmp_path):
    """Each robot of a links team may be given its own keypoints file and camera (the fusion
    of an online step): the team round-trips, each robot names its own keypoints file."""
    from pipeline.team.teamfile import check_data_files, keypoints_file_of

    data = {**_LINKS, "keypoints": ["k0.csv", "k1.csv", "k2.csv"], "cameras": [_CAM] * 3}
    p = tmp_path / "TEAM.json"
    p.write_text(json.dumps(_doc(data=data, options={"fusion": True})))
    team = load_team(p)
    assert parse_team(team.to_json()).to_json() == team.to_json()
    assert keypoints_file_of(team, 2) == tmp_path / "k2.csv"
    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j\n")
    with pytest.raises(InputError, match=r"data.keypoints\[1\]"):
        check_data_files(team, 1)
    (tmp_path / "k1.csv").write_text("x,y\n")
    assert [w for w, _ in check_data_files(team, 1)] == [
        "data.links of the team file", "data.keypoints[1] of the team file"]
