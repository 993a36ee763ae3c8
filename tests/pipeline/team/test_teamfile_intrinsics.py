"""A team file's ``data.intrinsics`` (and a links team's ``data.cameras[i].K``) must be pinhole
matrices with positive focal lengths, as a K.txt is: a zero K left its robot with no match at
all ('intrinsics K are singular') and a run that ended as if the images did not overlap, a
negative focal length was used as given."""

import pytest

from pipeline.errors import InputError
from pipeline.inputs.photos import read_k_txt
from pipeline.team.teamfile import parse_team

GOOD = [[300.0, 0.0, 160.0], [0.0, 300.0, 120.0], [0.0, 0.0, 1.0]]


def _doc(K):
    return {"version": 1, "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7100 + i}"}
                                     for i in range(2)],
            "comm_edges": [[0, 1]],
            "data": {"kind": "images", "images": ["a.jpg", "b.jpg"], "intrinsics": [GOOD, K]}}


@pytest.mark.parametrize("K", [
    [[0.0, 0, 0], [0, 0, 0], [0, 0, 0]],
    [[-300.0, 0, 160], [0, 300, 120], [0, 0, 1]],
    [[300.0, 0, 160], [0, 0, 120], [0, 0, 1]],
    [[300.0, 0, 160], [0, 300, 120], [0, 0, 2]],
    [[300.0, 0, 160], [5, 300, 120], [0, 0, 1]]])
def test_intrinsics_that_are_no_pinhole_matrix_are_refused(K):
    with pytest.raises(InputError, match=r"data.intrinsics\[1\] K = .* is not a pinhole matrix "
                                         r"with positive focal lengths"):
        parse_team(_doc(K))


def test_pinhole_intrinsics_with_a_skew_are_read():
    team = parse_team(_doc([[300.0, 0.5, 160], [0, 310, 120], [0, 0, 1]]))
    assert team.data["intrinsics"][1][0][1] == 0.5


@pytest.mark.parametrize("K", [[[-100.0, 0, 50], [0, 100, 40], [0, 0, 1]],
                               [[100.0, 0, 50], [0, 100, 40], [0, 1, 1]]])
def test_a_links_team_camera_whose_k_is_no_pinhole_matrix_is_refused(K):
    cam = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0],
                                                                    [0, 0, 1]],
           "t": [0.0, 0.0, 1.5]}
    doc = _doc(None)
    doc["data"] = {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2],
                   "keypoints": ["k0", "k1"], "cameras": [cam, {**cam, "K": K}]}
    with pytest.raises(InputError, match=r"data.cameras\[1\].K = .* is not a pinhole matrix "
                                         r"with positive focal lengths"):
        parse_team(doc)


@pytest.mark.parametrize("skew", [1e9, 160.0, -31.0])
def test_intrinsics_with_a_skew_read_k_txt_refuses_are_refused(skew):
    # a K.txt with cx written where the skew goes (160 = cx, 0.53 x fx) is refused by
    # read_k_txt; the team file said it took what read_k_txt takes and passed it on
    K = [[300.0, skew, 160], [0, 300, 120], [0, 0, 1]]
    with pytest.raises(InputError, match=r"data.intrinsics\[1\] K = .* skew \|s\| at most 0.1 x fx"):
        parse_team(_doc(K))
    doc = _doc(None)
    cam = {"K": GOOD, "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0.0, 0.0, 1.5]}
    doc["data"] = {"kind": "links", "links": "in.csv", "features_per_camera": [2, 2],
                   "keypoints": ["k0", "k1"], "cameras": [cam, {**cam, "K": K}]}
    with pytest.raises(InputError, match=r"data.cameras\[1\].K = .* skew \|s\| at most 0.1 x fx"):
        parse_team(doc)


@pytest.mark.parametrize("skew", [0.0, 0.5, 30.0, -30.0, 30.000001, 1e9])
def test_the_team_file_takes_the_intrinsics_read_k_txt_takes(tmp_path, skew):
    K = [[300.0, skew, 160], [0, 300, 120], [0, 0, 1]]
    path = tmp_path / "K.txt"
    path.write_text("\n".join(" ".join(repr(float(v)) for v in row) for row in K) + "\n")
    try:
        read_k_txt(path)
        by_file = True
    except InputError:
        by_file = False
    try:
        parse_team(_doc(K))
        by_team = True
    except InputError:
        by_team = False
    assert by_team == by_file
