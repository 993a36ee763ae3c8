"""The robot program's own inputs: a links team's keypoints files and cameras."""

import json

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.team.robot import links_camera, write_keypoints
from pipeline.team.teamfile import load_team

_CAM = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": np.eye(3).tolist(),
        "t": [0.1, -0.2, 1.5]}


def _team(tmp_path, counts=(3, 2)):
    data = {"kind": "links", "links": "in.csv", "features_per_camera": list(counts),
            "keypoints": ["k0.csv", "k1.csv"], "cameras": [_CAM, {**_CAM, "t": [1.0, 0, 2]}]}
    doc = {"version": 1, "name": "t", "comm_edges": [[0, 1]], "data": data,
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(2)]}
    (tmp_path / "TEAM.json").write_text(json.dumps(doc))
    return load_team(tmp_path / "TEAM.json")


def test_a_robot_reads_back_its_own_keypoints_and_camera_exactly(tmp_path):
    kp = np.random.default_rng(0).uniform(0, 640, (3, 2)).astype(np.float32)
    write_keypoints(tmp_path / "k0.csv", kp)
    team = _team(tmp_path)
    got, (K, R, t) = links_camera(team, 0)
    assert got.dtype == np.float32 and np.array_equal(got, kp)
    assert np.array_equal(K, np.array(_CAM["K"])) and np.array_equal(R, np.eye(3))
    assert t.tolist() == [0.1, -0.2, 1.5]


def test_a_links_team_without_cameras_gives_none(tmp_path):
    doc = json.loads(_team(tmp_path).path.read_text())
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
    team = _team(tmp_path)
    (tmp_path / "k1.csv").write_text(text)
    with pytest.raises(InputError) as e:
        links_camera(team, 1)
    assert words in str(e.value) and "\n" not in str(e.value)
