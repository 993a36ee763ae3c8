"""robot, as a hostile user would run it: every bad TEAM.json, --id or --result is one line on
stderr naming the bad value (exit 2, no traceback, nothing written) before the robot opens its
Zenoh session; only the port-in-use case opens one."""

import json
import os
import socket
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import refused, run_capped, tree  # noqa: E402


def _doc(**over):
    doc = {"version": 1, "name": "t", "comm_edges": [[0, 1], [1, 2]],
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{17300 + i}"} for i in range(3)],
           "data": {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2, 2]},
           "options": {"start_timeout_s": 1.0}}
    doc.update(over)
    return doc


@pytest.fixture
def team_dir(tmp_path):
    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,1,2,1\n")
    return tmp_path


@pytest.fixture(autouse=True)
def no_session(monkeypatch):
    """A case that reached the robot's session would fail here instead of waiting for its
    neighbours: every case below must stop before."""
    import pipeline.team.robot as teamrobot

    def opened(*a, **k):
        raise AssertionError("the robot opened its session")

    monkeypatch.setattr(teamrobot, "run_robot_process", opened)


def _write(folder, doc=None, raw=None):
    p = folder / "TEAM.json"
    if raw is not None:
        p.write_bytes(raw)
    else:
        p.write_text(json.dumps(doc if doc is not None else _doc()))
    return p


def _robot(team, rid="0", *extra):
    return ["robot", "--team", str(team), "--id", str(rid), *map(str, extra)]


# --- the team file itself ------------------------------------------------------------------

def test_team_file_missing_folder_or_device(team_dir, capsys):
    refused(capsys, _robot(team_dir / "nope.json"), team_dir, "not found")
    refused(capsys, _robot(team_dir), team_dir, "is a folder")
    refused(capsys, _robot("/dev/null"), team_dir, "not a regular file")


@pytest.mark.parametrize("raw, needle", [
    (b"", "is not valid JSON"),
    (b"\x80\xff\x00binary", "is not valid JSON"),
    (json.dumps(_doc()).encode()[:50], "is not valid JSON"),
    (b"[1, 2]", "expected a JSON object at the top, got list"),
    (b"[" * 100_000 + b"]" * 100_000, "nests lists or objects too deeply"),
    (json.dumps(_doc()).replace('"start_timeout_s": 1.0', '"start_timeout_s": NaN').encode(),
     "option start_timeout_s nan"),
    (json.dumps(_doc()).replace('"start_timeout_s": 1.0',
                                '"start_timeout_s": Infinity').encode(),
     "option start_timeout_s inf"),
], ids=["empty", "binary", "truncated", "array", "deep-nesting", "nan", "infinity"])
def test_malformed_team_file(team_dir, capsys, raw, needle):
    refused(capsys, _robot(_write(team_dir, raw=raw)), team_dir, needle)


@pytest.mark.parametrize("rid", ["-1", "3", "abc", "1.0", "nan", "99999999999999999999", ""])
def test_id_outside_the_team(team_dir, capsys, rid):
    refused(capsys, _robot(_write(team_dir), rid), team_dir,
            f"--id {rid}: not a robot of team 't'; its robots are 0..2")


def _three(first):
    return [first, {"id": 1, "endpoint": "tcp/127.0.0.1:17301"},
            {"id": 2, "endpoint": "tcp/127.0.0.1:17302"}]


@pytest.mark.parametrize("over, needle", [
    ({"robots": None}, "'robots' must list at least 2 robots"),
    ({"robots": {"0": "x"}}, "'robots' must list at least 2 robots"),
    ({"robots": _three({"id": "0", "endpoint": "tcp/127.0.0.1:17300"})}, "id '0' must be an "
                                                                         "integer"),
    ({"robots": _three({"id": 0.0, "endpoint": "tcp/127.0.0.1:17300"})}, "id 0.0 must be an "
                                                                         "integer"),
    ({"robots": _three({"id": True, "endpoint": "tcp/127.0.0.1:17300"})}, "id True must be"),
    ({"robots": [{"id": 0, "endpoint": "tcp/h:1"}, {"id": 10**12, "endpoint": "tcp/h:2"}]},
     "id 1 is missing"),
    ({"robots": [{"id": 0, "endpoint": "tcp/h:1"}, {"id": 0, "endpoint": "tcp/h:2"}]},
     "robot id 0 is listed twice"),
    ({"robots": _three({"id": 0})}, "robots[0] must be an object with 'id' and 'endpoint'"),
    ({"robots": _three({"id": 0, "endpoint": "tcp/h:1", "colour": 1})},
     "robots[0] has unknown key 'colour'"),
    ({"comm_edges": [[0, 1, 2], [0, 1, 2]]}, "comm edge [0, 1, 2] must be a pair"),
    ({"comm_edges": [[0.5, 1]]}, "comm edge [0.5, 1] must be a pair [i, j] of integer"),
    ({"comm_edges": [["0", "1"]]}, "comm edge ['0', '1']"),
    ({"comm_edges": [[True, False]]}, "comm edge [True, False]"),
    ({"comm_edges": [[0, 10**30]]}, "must join two different robots 0..2"),
    ({"comm_edges": [[1, 1]]}, "comm edge [1, 1] must join two different robots"),
    ({"comm_edges": [[0, 1], [2]]}, "comm edge [2] must be a pair"),
    ({"comm_edges": [[0, 1], [1, 0]]}, "comm edge (0, 1) is listed more than once"),
    ({"comm_edges": None}, "'comm_edges' must be a list"),
    ({"comm_edges": {"0": 1}}, "'comm_edges' must be a list"),
    ({"data": None}, "'data' must be an object with kind"),
    ({"data": {"kind": "video"}}, "'data' must be an object with kind"),
    ({"data": {"kind": "links"}}, "data.links must be the path"),
    ({"data": {"kind": "links", "links": "in.csv", "features_per_camera": [2**62, 2, 2]}},
     "data.features_per_camera must list 3 counts in 0..5000000"),
    ({"data": {"kind": "links", "links": "in.csv", "features_per_camera": [2.5, 2, 2]}},
     "data.features_per_camera"),
    ({"data": {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2, 2], "x": 1}},
     "data of kind links has unknown key 'x'"),
    ({"data": {"kind": "formation", "robots": 3, "seed": "x"}}, "data.seed 'x'"),
    ({"data": {"kind": "formation", "robots": 3, "seed": -5}}, "data.seed -5"),
    ({"data": {"kind": "formation", "robots": 3, "size": [-640, 480]}}, "at least 64x48"),
    ({"data": {"kind": "formation", "robots": 3, "size": [100000, 100000]}}, "too large"),
    ({"data": {"kind": "formation", "robots": 3, "size": "640x480"}}, "data.size '640x480'"),
    ({"data": {"kind": "formation", "robots": "3"}}, "data.robots '3'"),
    ({"data": {"kind": "formation", "formation": 4, "robots": 3}}, "data.formation 4"),
    ({"data": {"kind": "images", "images": ["a.jpg"]}}, "one image path per robot (3)"),
    ({"data": {"kind": "images", "images": ["a", "b", "c"], "max_size": -5}},
     "data.max_size -5"),
    ({"data": {"kind": "images", "images": ["a", "b", "c"],
               "intrinsics": [[[float("nan")] * 3] * 3, None, None]}},
     "data.intrinsics[0] must be a 3x3 matrix of finite numbers"),
    ({"data": {"kind": "images", "images": ["a", "b", "c"],
               "intrinsics": [[["a"] * 3] * 3, None, None]}}, "data.intrinsics[0]"),
    ({"data": {"kind": "images", "images": ["a", "b", "c"], "intrinsics_known": "yes"}},
     "data.intrinsics_known must list 3 true/false values"),
    ({"options": "x"}, "'options' must be an object"),
    ({"options": {"speed": 1}}, "unknown option 'speed'"),
    ({"options": {"drop_prob": float("nan")}}, "option drop_prob nan"),
    ({"options": {"drop_prob": "0.1"}}, "option drop_prob '0.1'"),
    ({"options": {"drop_prob": 1.0}}, "option drop_prob 1.0 must be in [0, 1)"),
    ({"options": {"round_timeout_s": -1}}, "option round_timeout_s -1"),
    ({"options": {"round_timeout_s": 1e308}}, "option round_timeout_s 1e+308 must be a number "
                                              "of seconds in (0, 86400]"),
    ({"options": {"start_timeout_s": 1e308}}, "option start_timeout_s 1e+308"),
    ({"options": {"round_timeout_s": 0.05}}, "option round_timeout_s 0.05 is shorter than 1 s: "
                                             "a live neighbour beats every 0.2 s at most"),
    ({"robot_options": {"1": {"round_timeout_s": 0.1}}}, "option round_timeout_s 0.1 is shorter"),
    ({"options": {"loss_timeout": 10**18}}, "option loss_timeout 1000000000000000000 must be "
                                            "an integer in 1..100000"),
    ({"options": {"loss_timeout": 0}}, "option loss_timeout 0"),
    ({"options": {"max_features": 10**18}}, "option max_features 1000000000000000000"),
    ({"options": {"max_features": -1}}, "option max_features -1"),
    ({"options": {"fault_seed": -5}}, "option fault_seed -5 must be an integer >= 0"),
    ({"options": {"fault_seed": "x"}}, "option fault_seed 'x'"),
    ({"options": {"fault_seed": 1.5}}, "option fault_seed 1.5"),
    ({"options": {"merge_radius": -1}}, "option merge_radius -1"),
    ({"options": {"merge_radius": "x"}}, "option merge_radius 'x'"),
    ({"options": {"features": "nope"}}, "option features 'nope' must be one of"),
    ({"options": {"fusion": "yes"}}, "option fusion 'yes' must be true or false"),
    ({"options": {"rootsift": "yes"}}, "option rootsift 'yes'"),
    ({"options": {"budget_after_merge": 2}}, "option budget_after_merge 2"),
    ({"options": {"shared_memory": "no"}}, "option shared_memory 'no' must be true or false"),
    ({"options": {"threshold_px": float("inf")}}, "option threshold_px inf"),
    ({"options": {"resolution": "x"}}, "option resolution 'x'"),
    ({"robot_options": {"5": {}}}, "robot_options key '5' must be a robot id 0..2"),
    ({"robot_options": {"x": {}}}, "robot_options key 'x'"),
    ({"robot_options": {"1.0": {}}}, "robot_options key '1.0'"),
    ({"robot_options": {"1": "x"}}, "robot_options key '1'"),
    ({"robot_options": {"1": {"drop_prob": 2}}}, "option drop_prob 2"),
    ({"robot_options": [["1", {}]]}, "'robot_options' must be an object"),
    ({"observer": "tcp/127.0.0.1:1"}, "'observer' 'tcp/127.0.0.1:1' must be an object"),
    ({"observer": {"endpoint": "x"}}, "observer endpoint 'x'"),
    ({"observer": {"endpoint": "tcp/127.0.0.1:17300"}}, "is robot 0's"),
    ({"version": 2}, "version 2 is not supported"),
    ({"version": "1"}, "version '1' is not supported"),
    ({"name": "a b"}, "name 'a b'"),
    ({"name": 5}, "name 5"),
    ({"colour": 1}, "unknown key 'colour'"),
])
def test_malformed_team(team_dir, capsys, over, needle):
    refused(capsys, _robot(_write(team_dir, _doc(**over))), team_dir, needle, "TEAM.json")


@pytest.mark.parametrize("endpoint", [
    "127.0.0.1:7447", "tcp/127.0.0.1", "tcp/127.0.0.1:0", "tcp/127.0.0.1:65536",
    "tcp/127.0.0.1:abc", "tcp/:7447", "tcp/host name:1", 7447, None, ["tcp/h:1"],
])
def test_endpoint_that_is_not_host_port(team_dir, capsys, endpoint):
    doc = _doc(robots=_three({"id": 0, "endpoint": endpoint}))
    refused(capsys, _robot(_write(team_dir, doc)), team_dir,
            f"robot 0 endpoint {endpoint!r} must look like tcp/HOST:PORT")


@pytest.mark.parametrize("endpoint, fixed", [("tcp/::1:7447", "tcp/[::1]:7447"),
                                              ("tls/fe80::1:7447", "tls/[fe80::1]:7447")])
def test_an_ipv6_endpoint_without_brackets_is_refused_with_the_bracketed_form(
        team_dir, capsys, endpoint, fixed):
    """``tcp/::1:7447`` (an IPv6 address as written elsewhere) was refused as not
    ``tcp/HOST:PORT`` only; the line now gives the form that works."""
    doc = _doc(robots=_three({"id": 0, "endpoint": endpoint}))
    refused(capsys, _robot(_write(team_dir, doc)), team_dir,
            f"robot 0 endpoint {endpoint!r} must look like tcp/HOST:PORT with a port in "
            f"1..65535 (an IPv6 address goes in brackets: {fixed})")
    doc = _doc(observer={"endpoint": endpoint})
    refused(capsys, _robot(_write(team_dir, doc)), team_dir,
            f"observer endpoint {endpoint!r} must look like tcp/HOST:PORT with a port in "
            f"1..65535 (an IPv6 address goes in brackets: {fixed})")


def test_shared_endpoint_in_a_huge_team_is_found_in_bounded_time(team_dir, capsys):
    """200,000 robots: parsed in about a second; the first shared endpoint is named."""
    doc = _doc(robots=[{"id": i, "endpoint": f"tcp/127.0.0.1:{1 + i % 65000}"}
                       for i in range(200_000)])
    refused(capsys, _robot(_write(team_dir, doc)), team_dir,
            "robots 0 and 65000 share endpoint 'tcp/127.0.0.1:1'")


# --- what the robot reads and writes -------------------------------------------------------

@pytest.mark.parametrize("data, needle", [
    ({"kind": "links", "links": "nope.csv", "features_per_camera": [2, 2, 2]}, "no such file"),
    ({"kind": "links", "links": ".", "features_per_camera": [2, 2, 2]}, "is a folder"),
    ({"kind": "images", "images": ["a.jpg", "b.jpg", "c.jpg"]}, "data.images[0]"),
    ({"kind": "formation", "formation": "z", "robots": 3}, "unknown formation 'z'"),
    ({"kind": "formation", "formation": "d", "robots": 3, "graph": "nope"},
     "unknown graph kind 'nope'"),
], ids=["links-missing", "links-folder", "image-missing", "formation", "graph"])
def test_data_the_robot_cannot_use_fails_before_its_session(team_dir, capsys, data, needle):
    refused(capsys, _robot(_write(team_dir, _doc(data=data))), team_dir, needle)


@pytest.mark.parametrize("case, needle", [
    ("team", "is the input file given as --team"),
    ("links", "is the input file given as data.links of the team file"),
    ("folder", "is a folder"),
    ("devnull", "is not a regular file"),
    ("symlink", "is a symbolic link"),
    ("exists", "already exists; pass --overwrite"),
])
def test_result_that_names_an_input_or_a_special_entry(team_dir, capsys, case, needle):
    team = _write(team_dir)
    result = {"team": team, "links": team_dir / "in.csv", "folder": team_dir,
              "devnull": "/dev/null", "symlink": team_dir / "ln.json",
              "exists": team_dir / "r.json"}[case]
    if case == "symlink":
        os.symlink(team_dir / "target.json", result)
    elif case == "exists":
        result.write_text("precious")
    refused(capsys, _robot(team, "0", "--result", result), team_dir, needle, "--result")
    assert not (team_dir / "target.json").exists()


def test_ctrl_c_is_one_line_exit_130(team_dir, capsys, monkeypatch):
    import pipeline.team.robot as teamrobot

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(teamrobot, "run_robot_process", interrupted)
    team = _write(team_dir)
    before = tree(team_dir)
    assert main(_robot(team, "0", "--result", team_dir / "r.json")) == 130
    err = capsys.readouterr().err
    assert err.startswith("interrupted: robot") and err.count("\n") == 1
    assert tree(team_dir) == before


def test_port_in_use_is_one_line(team_dir):
    """The one case that opens a Zenoh session: its listen endpoint is taken."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        doc = _doc(robots=[{"id": 0, "endpoint": f"tcp/127.0.0.1:{port}"},
                           {"id": 1, "endpoint": "tcp/127.0.0.1:17301"},
                           {"id": 2, "endpoint": "tcp/127.0.0.1:17302"}])
        p = run_capped(["robot", "--team", _write(team_dir, doc), "--id", "0"], timeout=60)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and f"cannot listen on tcp/127.0.0.1:{port}" in lines[0]
    assert "the port is in use" in lines[0] and ".cargo" not in lines[0]


def test_an_address_not_of_this_host_is_named_as_such(team_dir):
    """An endpoint on an address this host does not have is not called a port in use."""
    doc = _doc(robots=[{"id": 0, "endpoint": "tcp/192.0.2.1:17300"},
                       {"id": 1, "endpoint": "tcp/127.0.0.1:17301"},
                       {"id": 2, "endpoint": "tcp/127.0.0.1:17302"}])
    p = run_capped(["robot", "--team", _write(team_dir, doc), "--id", "0"], timeout=60)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "cannot listen on tcp/192.0.2.1:17300" in lines[0]
    assert "port is in use" not in lines[0] and ".cargo" not in lines[0]


def test_a_team_file_names_its_feature_method_from_the_pipelines_list_without_opencv():
    """One list of feature methods (pipeline.matching.methods): a team file naming an unknown
    one is refused with that list, and checking it loads no OpenCV (the observer and the
    launcher parse team files)."""
    import json
    import subprocess
    import sys

    doc = {"version": 1, "name": "methods", "comm_edges": [[0, 1]],
           "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:17001"},
                      {"id": 1, "endpoint": "tcp/127.0.0.1:17002"}],
           "data": {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1]},
           "options": {"features": "brisk"}}
    code = ("import json, sys\n"
            "from pipeline.errors import InputError\n"
            "from pipeline.team.teamfile import parse_team\n"
            "try:\n"
            f"    parse_team({doc!r})\n"
            "except InputError as exc:\n"
            "    print(json.dumps([str(exc), 'cv2' in sys.modules]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    message, opencv = json.loads(out.stdout.strip().splitlines()[-1])
    assert "option features 'brisk' must be one of sift, orb, akaze, surf, colmap-sift" in message
    assert not opencv


def test_links_beyond_the_declared_feature_counts_are_named(tmp_path):
    """A case that needs the robots' sessions: the ids are known only once a robot reads its
    rows of the links file; it fails with one line, which the launcher names."""
    from pipeline.errors import TeamError
    from pipeline.team.launcher import launch_team, make_team

    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j\n0,5,1,0\n")
    team = make_team("t", [[0, 1]], {"kind": "links", "links": str(tmp_path / "in.csv"),
                                      "features_per_camera": [2, 2]}, n=2)
    with pytest.raises(TeamError, match=r"exit code 2: error: robot \d: link \(0,5\)-\(1,0\)|"
                                        r"exit code 2: error: robot 1: link \(1,0\)-\(0,5\)"):
        launch_team(team, tmp_path / "team", timeout_s=60)
