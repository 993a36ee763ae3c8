"""A K.txt whose fy is ten times its fx (a digit added, or one lost in fx) was taken as it
was: matching and fusion used both focal lengths while the COLMAP stages used one,
sqrt(fx fy), and the run went on with the stages seeing two cameras. fx and fy more than
MAX_FOCAL_RATIO (2) times apart are now an InputError naming both; a calibration's, and an
anamorphic lens', are kept."""

import pytest

from pipeline.errors import InputError
from pipeline.inputs.photos import read_k_txt


def _k(tmp_path, fx, fy, four=False):
    path = tmp_path / "K.txt"
    path.write_text(f"{fx} {fy} 320 240\n" if four else f"{fx} 0 320\n0 {fy} 240\n0 0 1\n")
    return path


@pytest.mark.parametrize(("fx", "fy", "shown"), [
    (800, 8000, r"fy = 8000 is 10 x fx \(800\)"),
    (800, 80, r"fy = 80 is 0.1 x fx \(800\)"),
    (8000, 800, r"fy = 800 is 0.1 x fx \(8000\)"),
    (800, 1601, r"fy = 1601 is 2 x fx \(800\)"),
])
@pytest.mark.parametrize("four", [False, True], ids=["matrix", "fx-fy-cx-cy"])
def test_focal_lengths_more_than_twice_apart_are_refused(tmp_path, fx, fy, shown, four):
    path = _k(tmp_path, fx, fy, four)
    with pytest.raises(InputError, match=rf"^intrinsics file '{path}': {shown}; fx and fy are "
                                         r"one focal length .* at most 2x apart\), and the "
                                         r"COLMAP stages use one, sqrt\(fx fy\)"):
        read_k_txt(path)


@pytest.mark.parametrize(("fx", "fy"), [(800, 800), (800, 808.5), (1000, 1333), (1600, 800)])
def test_a_calibrations_focal_lengths_are_kept(tmp_path, fx, fy):
    K = read_k_txt(_k(tmp_path, fx, fy))
    assert (K[0, 0], K[1, 1]) == (fx, fy)


@pytest.mark.parametrize("fy", [300.0, 600.0, 600.5, 149.9, 3000.0])
def test_the_team_file_takes_the_focal_lengths_read_k_txt_takes(tmp_path, fy):
    from pipeline.team.teamfile import parse_team

    K = [[300.0, 0.0, 160.0], [0.0, fy, 120.0], [0.0, 0.0, 1.0]]
    path = tmp_path / "K.txt"
    path.write_text("\n".join(" ".join(repr(v) for v in row) for row in K) + "\n")
    doc = {"version": 1, "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7100 + i}"}
                                    for i in range(2)],
           "comm_edges": [[0, 1]],
           "data": {"kind": "images", "images": ["a.jpg", "b.jpg"], "intrinsics": [K, K]}}
    by_file = by_team = True
    try:
        read_k_txt(path)
    except InputError:
        by_file = False
    try:
        parse_team(doc)
    except InputError as exc:
        by_team = False
        assert "fx and fy > 0 and at most 2 times apart" in str(exc)
    assert by_team == by_file == (150.0 <= fy <= 600.0)
