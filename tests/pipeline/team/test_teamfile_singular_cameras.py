"""A TEAM.json camera that is no finite camera (a singular K, R or K R) is refused when the
file is read, naming it, instead of its robot's geometric test refusing every point through it
(or its fusion stopping on a singular matrix)."""

import pytest

from pipeline.errors import InputError
from pipeline.team.teamfile import parse_team

_CAM = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "t": [0.0, 0.0, 1.5]}


def _doc(cameras):
    return {"version": 1, "name": "t", "comm_edges": [[0, 1], [1, 2]],
            "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(3)],
            "data": {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2, 2],
                     "keypoints": ["k0", "k1", "k2"], "cameras": cameras}}


@pytest.mark.parametrize("cam, words", [
    ({**_CAM, "K": [[0, 0, 0], [0, 0, 0], [0, 0, 0]]}, "data.cameras[1].K is singular"),
    ({**_CAM, "R": [[1, 0, 0], [0, 1, 0], [0, 0, 0]]}, "data.cameras[1].R is singular"),
    ({"P": [[0, 0, 0, 0]] * 3}, "data.cameras[1].P: its left 3x3 block (K R) is singular"),
])
def test_a_singular_camera_is_refused(cam, words):
    with pytest.raises(InputError) as e:
        parse_team(_doc([_CAM, cam, None]))
    assert words in str(e.value)


def test_finite_cameras_parse():
    P = [[100.0, 0, 50, 0], [0, 100.0, 40, 0], [0, 0, 1, 1.5]]
    assert parse_team(_doc([_CAM, {"P": P}, None])).n == 3
