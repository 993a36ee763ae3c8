import json
import re

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.team.robot import links_camera, links_projection, write_keypoints
from pipeline.team.teamfile import load_team, parse_team

_LINKS = {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2, 2]}
_MATCH = {"kind": "online-match", "step": 2, "window": 3, "frames": ["f0.npz", "f1.npz", "f2.npz"],
          "store": ["r0", "r1", "r2"]}
_CAM = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "t": [0.0, 0.0, 1.5]}


def _doc(**over):
    doc = {"version": 1, "name": "t", "comm_edges": [[0, 1], [1, 2]],
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(3)],
           "data": {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2, 2]}}
    doc.update(over)
    return doc


def test_an_online_match_team_parses_and_names_a_missing_frame(tmp_path):
    from pipeline.team.teamfile import check_data_files

    path = tmp_path / "TEAM.json"
    path.write_text(json.dumps(_doc(data=_MATCH)))
    team = load_team(path)
    assert team.data["step"] == 2 and team.resolve_path(team.data["store"][1]) == tmp_path / "r1"
    with pytest.raises(InputError, match=r"data.frames\[1\]"):
        check_data_files(team, 1)


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
    ({"robots": [{"id": 0, "endpoint": "udp/h:1"}, {"id": 1, "endpoint": "tcp/h:2"}]},
     "udp may lose a round's packet"),
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
     "data.cameras[1] must be an object with exactly \"K\", \"R\" and \"t\" (a pose), "
     "exactly \"P\" (a projection) or null (unknown); unknown key 'dist'"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"],
               "cameras": [_CAM, {"P": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}, None]}},
     "data.cameras[1].P must be a 3x4 matrix of finite numbers"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"],
               "cameras": [_CAM, {"P": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]}, None]},
      "options": {"fusion": True}},
     "options sets fusion on a links team without data.keypoints and every robot's pose"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"],
               "cameras": [_CAM, _CAM, {**_CAM, "R": [[1, 0], [0, 1]]}]}},
     "data.cameras[2].R must be a 3x3 matrix"),
    ({"data": {**_LINKS, "keypoints": ["k0", "k1", "k2"],
               "cameras": [{**_CAM, "t": [0, 0, "1"]}, _CAM, _CAM]}},
     "data.cameras[0].t [0, 0, '1'] must be 3 finite numbers"),
    ({"data": {**_LINKS, "history": ["h0.npz", "h1.npz"]}},
     "data.history must list 3 paths, one history file per robot"),
    ({"data": {**_LINKS, "history": "h.npz"}}, "data.history must list 3 paths"),
    ({"data": {**_LINKS, "weights": ["w0.csv", "w1.csv", "w2.csv"]}},
     "data.weights must list 3 paths, one weights file per robot (a row per row of its own "
     "links file), with data.links a list"),
    ({"data": {**_LINKS, "links": ["l0.csv", "l1.csv", "l2.csv"], "weights": ["w0.csv"]}},
     "data.weights must list 3 paths"),
    ({"options": {"fusion": True}}, "options sets fusion on a links team without data.keypoints"),
    ({"data": {**_MATCH, "step": -1}}, "data.step -1 must be an integer >= 0"),
    ({"data": {**_MATCH, "window": 0}}, "data.window 0 must be an integer >= 1"),
    ({"data": {**_MATCH, "frames": ["f0.npz"]}}, "data.frames must list 3 paths, one frame file"),
    ({"data": {**_MATCH, "store": "robots"}}, "data.store must list 3 paths, one folder"),
    ({"data": {**_MATCH, "links": "in.csv"}}, "data of kind online-match has unknown key 'links'"),
    ({"data": {**_MATCH, "resend": 1}}, "data.resend 1 must be true or false"),
    ({"data": {**_MATCH, "void": [6]}}, "data.void [6] must list frame ids of the window's "
     "earlier steps (0 to 5"),
    ({"data": {**_MATCH, "void": "3"}}, "data.void '3' must list frame ids"),
    ({"options": {"fusion": True}},
     "options sets fusion on a links team without data.keypoints"),
    # names every robot would refuse: observe refuses them too, not waiting for robots
    ({"data": {"kind": "formation", "formation": "zz", "robots": 3, "graph": "ring"}},
     "data.formation: unknown formation 'zz'"),
    ({"data": {"kind": "formation", "formation": "ring", "robots": 3, "graph": "star"}},
     "data.graph: unknown graph kind 'star'; choose one of line, ring"),
])
def test_malformed_team_is_one_line_error(over, words):
    with pytest.raises(InputError) as e:
        parse_team(_doc(**over))
    assert words in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("budget", ["x", -3, 0, 2.5, True, [4]])
def test_a_bundle_budget_that_is_not_a_set_size_is_refused(budget):
    """``bundle_budget`` was not checked: every robot of the team then stopped with a
    traceback (``int('x')``, a negative size) or cut a 2.5 to 2."""
    with pytest.raises(InputError) as e:
        parse_team(_doc(options={"bundle_budget": budget}))
    assert f"option bundle_budget {budget!r} must be an integer >= 1" in str(e.value)
    assert parse_team(_doc(options={"bundle_budget": 4})).options["bundle_budget"] == 4
    assert parse_team(_doc(options={"bundle_budget": None})).options["bundle_budget"] is None


@pytest.mark.parametrize("fusion", [False, True])
def test_fusion_is_the_teams_option_not_one_robots(fusion):
    """``robot_options: {"1": {"fusion": false}}`` was accepted: robot 1 skipped the fusion stage
    and ended while its neighbours ran it, so they wrote it off and cut all its links
    robot-lost. Fusion is now the team's, like the rule, and compared in the start hello."""
    formation = {"kind": "formation", "formation": "ring", "robots": 3, "size": [160, 120]}
    with pytest.raises(InputError, match=r"robot_options\['1'\] sets 'fusion', which is the "
                                         r"team's"):
        parse_team(_doc(data=formation, options={"fusion": not fusion},
                        robot_options={"1": {"fusion": fusion}}))
    t = parse_team(_doc(data=formation, options={"fusion": fusion}))
    assert t.shared_terms()["fusion"] is fusion


@pytest.mark.parametrize("key, value", [("features", "orb"), ("rootsift", True)])
def test_the_descriptor_kind_is_the_teams_option_not_one_robots(key, value):
    """``robot_options: {"1": {"features": "orb"}}`` was accepted: robot 1 extracted ORB, its
    neighbours matched its descriptors as their own SIFT and stopped on "cameras 0 and 1 have
    different descriptors (sift float32x128 vs sift uint8x32)", naming the wrong method. One
    kind of descriptor is now the team's, refused per robot and compared in the start hello."""
    formation = {"kind": "formation", "formation": "ring", "robots": 3, "size": [160, 120]}
    with pytest.raises(InputError, match=rf"robot_options\['1'\] sets '{key}', which is the "
                                         r"team's"):
        parse_team(_doc(data=formation, robot_options={"1": {key: value}}))
    assert parse_team(_doc(data=formation, options={key: value})).shared_terms()[key] == value


@pytest.mark.parametrize("key", ["options", "robot_options"])
@pytest.mark.parametrize("value", [[], "", 0, False])
def test_options_that_are_not_an_object_are_refused_even_when_empty(key, value):
    """``"options": []`` (or "", 0, false) passed as no options, where ``[1]`` was refused."""
    with pytest.raises(InputError, match=rf"'{key}' must be an object"):
        parse_team(_doc(**{key: value}))
    assert parse_team(_doc(**{key: None})).options["fusion"] is False


def _endpoints(*eps):
    return [{"id": i, "endpoint": ep} for i, ep in enumerate(eps)]


@pytest.mark.parametrize("first, second", [
    ("tcp/127.0.0.1:7001", "tcp/localhost:7001"),
    ("tcp/localhost:7001", "tcp/[::1]:7001"),
    ("tcp/LOCALHOST:7001", "tcp/localhost:7001"),
    ("tls/127.0.0.1:7001", "tcp/localhost:7001"),
])
def test_one_address_written_two_ways_is_a_shared_endpoint(first, second):
    """localhost and 127.0.0.1 are one listening address: the second robot could not bind."""
    with pytest.raises(InputError, match=(
            rf"robots 0 and 1 share endpoint '{re.escape(second)}' \(the address of robot 0's "
            rf"'{re.escape(first)}'\); each robot listens on its own")):
        parse_team(_doc(robots=_endpoints(first, second, "tcp/127.0.0.1:7002")))


def test_the_observer_on_a_robots_address_written_another_way_is_refused():
    with pytest.raises(InputError, match=r"observer endpoint 'tcp/localhost:7000' is robot 0's "
                                         r"\('tcp/127.0.0.1:7000', the same address\)"):
        parse_team(_doc(observer={"endpoint": "tcp/localhost:7000"}))


@pytest.mark.parametrize("endpoint", ["tcp/127.0.0.1:0", "tcp/127.0.0.1:99999"])
def test_an_observer_port_outside_1_to_65535_is_refused(endpoint):
    """Port 0 would listen on a port the system picks, where no robot connects; 99999 only
    failed when the observer opened its session, while every robot ran on unheard."""
    with pytest.raises(InputError, match=rf"observer endpoint '{re.escape(endpoint)}' must look "
                                         r"like tcp/HOST:PORT with a port in 1\.\.65535"):
        parse_team(_doc(observer={"endpoint": endpoint}))


@pytest.mark.parametrize("first, second", [
    ("tcp/127.0.0.1:7001", "tcp/localhost:7002"),      # other port
    ("tcp/127.0.0.1:7001", "quic/localhost:7001"),     # quic is UDP: another port space
    ("tcp/10.0.0.1:7001", "tcp/10.0.0.2:7001"),        # two machines
    ("tcp/robot-a.invalid:7001", "tcp/robot-b.invalid:7001"),  # names that do not resolve
])
def test_distinct_addresses_are_not_shared(first, second):
    t = parse_team(_doc(robots=_endpoints(first, second, "tcp/127.0.0.1:7003")))
    assert [r.endpoint for r in t.robots[:2]] == [first, second]


def test_robots_on_other_loopback_addresses_with_one_port_are_not_shared():
    """127.0.0.1:P, 127.0.0.2:P, 127.0.0.3:P bind apart (hosts simulated on one machine); every
    loopback address was one, so the team was refused as sharing an endpoint."""
    t = parse_team(_doc(robots=_endpoints("tcp/127.0.0.1:7001", "tcp/127.0.0.2:7001",
                                          "tcp/127.0.0.3:7001"),
                        observer={"endpoint": "tcp/127.0.0.9:7001"}))
    assert [r.endpoint for r in t.robots] == ["tcp/127.0.0.1:7001", "tcp/127.0.0.2:7001",
                                              "tcp/127.0.0.3:7001"]
    with pytest.raises(InputError, match="robots 0 and 1 share endpoint 'tcp/\\[::1\\]:7001'"):
        parse_team(_doc(robots=_endpoints("tcp/127.0.0.1:7001", "tcp/[::1]:7001",
                                          "tcp/127.0.0.3:7001")))


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


def test_a_team_file_saved_with_a_byte_order_mark_loads_and_utf16_is_named(tmp_path):
    """A TEAM.json edited in Notepad starts with a UTF-8 byte order mark: it was refused as
    "not valid JSON: Unexpected UTF-8 BOM (decode using utf-8-sig)"; it now loads as the file
    without it. A UTF-16 file is refused naming the encoding and what to do."""
    text = json.dumps(_doc())
    plain, bom, utf16 = (tmp_path / n for n in ("plain.json", "bom.json", "utf16.json"))
    plain.write_text(text, encoding="utf-8")
    bom.write_text(text, encoding="utf-8-sig")
    utf16.write_text(text, encoding="utf-16")
    assert bom.read_bytes().startswith(b"\xef\xbb\xbf")
    a, b = load_team(plain), load_team(bom)
    assert (a.name, a.comm_edges.tolist(), a.data, a.options) == \
        (b.name, b.comm_edges.tolist(), b.data, b.options)
    with pytest.raises(InputError, match=r"is not valid JSON: not UTF-8 text \(a UTF-16 file\) "
                                         r"\(byte 0xff at offset 0\); save it as UTF-8$"):
        load_team(utf16)


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


# a robot of a links team reads its own keypoints file and camera
# (pipeline.team.robot.links_camera)

_ROBOT_CAM = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": np.eye(3).tolist(),
              "t": [0.1, -0.2, 1.5]}


def _robot_team(tmp_path, counts=(3, 2)):
    data = {"kind": "links", "links": "in.csv", "features_per_camera": list(counts),
            "keypoints": ["k0.csv", "k1.csv"], "cameras": [_ROBOT_CAM, {**_ROBOT_CAM, "t": [1.0, 0, 2]}]}
    doc = {"version": 1, "name": "t", "comm_edges": [[0, 1]], "data": data,
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(2)]}
    (tmp_path / "TEAM.json").write_text(json.dumps(doc))
    return load_team(tmp_path / "TEAM.json")


def test_a_robot_reads_back_its_own_keypoints_and_camera_exactly(tmp_path):
    kp = np.random.default_rng(0).uniform(0, 640, (3, 2)).astype(np.float32)
    write_keypoints(tmp_path / "k0.csv", kp)
    team = _robot_team(tmp_path)
    got, (K, R, t) = links_camera(team, 0)
    assert got.dtype == np.float32 and np.array_equal(got, kp)
    assert np.array_equal(K, np.array(_ROBOT_CAM["K"])) and np.array_equal(R, np.eye(3))
    assert t.tolist() == [0.1, -0.2, 1.5]


def test_a_robot_knows_its_projection_from_its_pose_or_its_p_entry(tmp_path):
    """links_projection: K [R | t] of a pose, the P of a projection-only entry (no pose for
    fusion then), None where unknown; each robot its own entry."""
    P = np.arange(12, dtype=float).reshape(3, 4) + np.eye(3, 4)  # a finite camera
    doc = json.loads(_robot_team(tmp_path).path.read_text())
    doc["robots"].append({"id": 2, "endpoint": "tcp/127.0.0.1:7002"})
    doc["comm_edges"] = [[0, 1], [1, 2]]
    doc["data"].update(features_per_camera=[1, 1, 1], keypoints=["k0.csv", "k1.csv", "k2.csv"],
                       cameras=[_ROBOT_CAM, {"P": P.tolist()}, None])
    (tmp_path / "TEAM.json").write_text(json.dumps(doc))
    for k in range(3):
        write_keypoints(tmp_path / f"k{k}.csv", [[1.0, 2.0]])
    team = load_team(tmp_path / "TEAM.json")
    K, R, t = (np.array(_ROBOT_CAM[k], float) for k in "KRt")
    assert np.array_equal(links_projection(team, 0), K @ np.c_[R, t])
    assert np.array_equal(links_projection(team, 1), P) and links_camera(team, 1)[1] is None
    assert links_projection(team, 2) is None and links_camera(team, 2)[1] is None


def test_a_links_team_without_cameras_gives_none(tmp_path):
    doc = json.loads(_robot_team(tmp_path).path.read_text())
    del doc["data"]["keypoints"], doc["data"]["cameras"]
    (tmp_path / "TEAM.json").write_text(json.dumps(doc))
    assert links_camera(load_team(tmp_path / "TEAM.json"), 1) == (None, None)


@pytest.mark.parametrize("text, words", [
    ("u,v\n1,2\n1,2\n", "k1.csv:1: a keypoints file starts with the header x,y"),
    ("x,y\n1,2\n1,nan\n", "k1.csv:3: '1,nan' is not a keypoint x,y"),
    ("x,y\n1,2\n1\n", "k1.csv:3: '1' is not a keypoint"),
    ("x,y\n1,2\n", "1 keypoints, but data.features_per_camera gives robot 1 2 features"),
])
def test_bad_keypoints_file_is_one_line_error(tmp_path, text, words):
    team = _robot_team(tmp_path)
    (tmp_path / "k1.csv").write_text(text)
    with pytest.raises(InputError) as e:
        links_camera(team, 1)
    assert words in str(e.value) and "\n" not in str(e.value)


def test_an_ipv6_endpoint_parses():
    team = parse_team(_doc(robots=[{"id": 0, "endpoint": "tcp/[::1]:7447"},
                                   {"id": 1, "endpoint": "tcp/127.0.0.1:7448"},
                                   {"id": 2, "endpoint": "tcp/localhost:7449"}]))
    assert team.endpoint(0) == "tcp/[::1]:7447"


def test_a_links_team_without_a_rule_runs_resolves_default():
    """A hand-written links team without ``resolution`` ran the evidence rule while ``resolve``
    on the same links runs ``sync`` (DEFAULT_LINKS_RESOLUTION): the same links got other
    decisions by hand than through the command. A links team now takes resolve's default;
    a formation team keeps DEFAULT_RESOLUTION, and a rule given is kept."""
    from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION, DEFAULT_RESOLUTION

    links = {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1, 1]}
    formation = {"kind": "formation", "formation": "ring", "robots": 3, "size": [160, 120]}
    assert parse_team(_doc(data=links)).options["resolution"] == DEFAULT_LINKS_RESOLUTION
    assert parse_team(_doc(data=formation)).options["resolution"] == DEFAULT_RESOLUTION
    given = parse_team(_doc(data=links, options={"resolution": "paper"}))
    assert given.options["resolution"] == "paper"


@pytest.mark.parametrize("version", [True, 1.5, "1", 2])
def test_a_version_other_than_1_is_refused(version):
    """``"version": true`` passed as version 1 (Python's ``True == 1``)."""
    with pytest.raises(InputError, match=r"version .* is not supported \(use 1\)"):
        parse_team(_doc(version=version))
    assert parse_team(_doc(version=1.0)).n == 3


@pytest.mark.parametrize("robots", [0, 1, -3])
def test_a_formation_of_fewer_than_two_robots_is_named_as_written(robots):
    """data.robots 0 was read as the formation's default and refused as 'data describes 6
    robots', a count the file did not hold."""
    data = {"kind": "formation", "formation": "line", "robots": robots, "size": [320, 240]}
    with pytest.raises(InputError, match=rf"data.robots {robots}: give a number of robots from "
                                         r"2 to 1000"):
        parse_team(_doc(data=data))


def test_a_formation_of_null_robots_is_the_formation_s_six():
    data = {"kind": "formation", "formation": "line", "robots": None, "size": [320, 240]}
    with pytest.raises(InputError, match=r"data describes 6 robots but 'robots' lists 3"):
        parse_team(_doc(data=data))
    data["robots"] = 3
    assert parse_team(_doc(data=data)).n == 3


@pytest.mark.parametrize("first, second", [
    ("tcp/0.0.0.0:7001", "tcp/127.0.0.1:7001"),
    ("tcp/127.0.0.1:7001", "tcp/0.0.0.0:7001"),
    ("tcp/[::]:7001", "tcp/10.0.0.2:7001"),
])
def test_a_wildcard_address_shares_its_port_with_every_address(first, second):
    """A robot on 0.0.0.0 (or ::) listens on every address of its machine: the other robot
    could not bind that port, and the team was accepted until it failed at its start."""
    with pytest.raises(InputError, match=(
            rf"robots 0 and 1 share endpoint '{re.escape(second)}' \(robot 0's "
            rf"'{re.escape(first)}' on the same port: a wildcard address listens on every "
            r"address of its machine\); each robot listens on its own")):
        parse_team(_doc(robots=_endpoints(first, second, "tcp/127.0.0.1:7002")))


def test_a_wildcard_observer_on_a_robots_port_is_refused():
    with pytest.raises(InputError, match=r"observer endpoint 'tcp/0.0.0.0:7000' is robot 0's"):
        parse_team(_doc(observer={"endpoint": "tcp/0.0.0.0:7000"}))


def test_a_wildcard_address_on_other_ports_is_not_shared():
    t = parse_team(_doc(robots=_endpoints("tcp/0.0.0.0:7001", "tcp/127.0.0.1:7002",
                                          "quic/127.0.0.1:7001")))
    assert t.n == 3


@pytest.mark.parametrize("key", ["01", " 1", "+1"])
def test_a_robot_options_key_must_be_the_id_as_written(key):
    """'01' beside '1' were both robot 1: one object replaced the other, silently."""
    with pytest.raises(InputError, match=rf"robot_options key '{re.escape(key)}' must be a "
                                         r"robot id 0\.\.2 with an object of options"):
        parse_team(_doc(robot_options={"1": {"loss_timeout": 9}, key: {"loss_timeout": 50}}))


@pytest.mark.parametrize("text, words", [
    ("w\n1.5\n", "w1.csv:1: a weights file starts with the header weight"),
    ("weight\n1.5\nnan\n", "w1.csv:3: 'nan' is not a weight (one number, not nan)"),
    ("weight\n1.5\n1,2\n", "w1.csv:3: '1,2' is not a weight"),
    ("weight\n1.5\n", "w1.csv:3: 1 weights for the 2 rows of robot 1's links file"),
    ("weight\n1.5\n2\n3\n", "w1.csv:4: 3 weights for the 2 rows"),
    # a file that is not UTF-8 text was a UnicodeDecodeError's traceback
    (b"weight\n1.5\n\xff2\n", "w1.csv' is not a UTF-8 text file (invalid start byte at line 3)"),
    (b"\xff\xfew\x00e\x00", "w1.csv' is not a UTF-8 text file (UTF-16 or UTF-32"),
    # float() would have read it as 10
    ("weight\n1.5\n1_0\n", "w1.csv:3: '1_0' is not a weight"),
])
def test_bad_weights_file_is_one_line_error(tmp_path, text, words):
    """A links team's data.weights: each robot reads its own file, one weight per row of its
    own links file."""
    from pipeline.team.robot import links_weights

    doc = _doc(data={**_LINKS, "links": ["l0.csv", "l1.csv", "l2.csv"],
                     "weights": ["w0.csv", "w1.csv", "w2.csv"]})
    (tmp_path / "TEAM.json").write_text(json.dumps(doc))
    w1 = tmp_path / "w1.csv"
    w1.write_bytes(text) if isinstance(text, bytes) else w1.write_text(text)
    team = load_team(tmp_path / "TEAM.json")
    with pytest.raises(InputError) as e:
        links_weights(team, 1, 2)
    assert words in str(e.value) and "\n" not in str(e.value)
    (tmp_path / "w1.csv").write_text("weight\n1.5\n-2\n")
    assert links_weights(team, 1, 2).tolist() == [1.5, -2.0]
    (tmp_path / "w1.csv").write_text("weight\n-inf\ninf\n")  # the simulator's weights may be
    assert links_weights(team, 1, 2).tolist() == [-np.inf, np.inf]
    assert links_weights(load_team_without_weights(tmp_path), 1, 2) is None


def load_team_without_weights(tmp_path):
    (tmp_path / "T2.json").write_text(json.dumps(_doc()))
    return load_team(tmp_path / "T2.json")
