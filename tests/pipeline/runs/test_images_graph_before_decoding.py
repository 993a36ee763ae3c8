"""run-images reads a --graph file on the file (or robot sub-folder) names before it decodes
any image: a bad row is refused at once, not after every photograph of the folder was read
(0.13 s each at full size: minutes for a large folder)."""

import shutil
from pathlib import Path

import pytest

from pipeline.__main__ import main
from pipeline.inputs import photos

SCEAUX = Path(__file__).resolve().parents[2] / "data" / "sceaux_castle_640"
NAMES = ("100_7100.JPG", "100_7101.JPG", "100_7102.JPG")


@pytest.fixture
def no_decoding(monkeypatch):
    def refuse(path):
        raise AssertionError(f"{path} was decoded")

    monkeypatch.setattr(photos, "load_image", refuse)


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and "was decoded" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("row,message", [
    ("0,zz", "line 1: image 'zz' is not one of the 3 images"),
    ("0,7", "line 1: camera index 7 out of range 0..2 (3 images)"),
])
def test_a_bad_graph_file_is_refused_before_any_image_is_decoded(tmp_path, capsys, no_decoding,
                                                                 row, message):
    folder = tmp_path / "photos"
    folder.mkdir()
    for name in NAMES:
        shutil.copy(SCEAUX / name, folder / name)
    graph = tmp_path / "g.csv"
    graph.write_text(f"{row}\n")
    out = tmp_path / "run"
    assert main(["run-images", str(folder), "--graph", str(graph), "--no-rerun",
                 "--out", str(out)]) == 2
    assert _error_line(capsys) == f"error: {graph}, {message}" + (
        " (100_7100.JPG, 100_7101.JPG, 100_7102.JPG)" if "zz" in row else "")
    assert not out.exists()


def _two_robots(tmp_path):
    """A sequence folder of robots a and b, two photographs each."""
    team = tmp_path / "team"
    for robot in ("a", "b"):
        (team / robot).mkdir(parents=True)
        for k, name in enumerate(NAMES[:2]):
            shutil.copy(SCEAUX / name, team / robot / f"f{k}.jpg")
    return team


def test_a_bad_robot_graph_file_is_refused_before_any_frame_is_decoded(tmp_path, capsys,
                                                                       no_decoding):
    team = _two_robots(tmp_path)
    graph = tmp_path / "robots.csv"
    graph.write_text("a,zz\n")
    out = tmp_path / "run"
    assert main(["run-images", str(team), "--sequence", "--graph", str(graph), "--no-rerun",
                 "--out", str(out)]) == 2
    assert _error_line(capsys) == (f"error: {graph}, line 1: robot 'zz' is not one of the 2 "
                                   "robots (a, b)")
    assert not out.exists()


def test_knn_is_refused_for_a_sequence_before_any_frame_is_decoded(tmp_path, capsys,
                                                                   no_decoding):
    team = _two_robots(tmp_path)
    assert main(["run-images", str(team), "--sequence", "--graph", "knn:1", "--no-rerun",
                 "--out", str(tmp_path / "run")]) == 2
    assert _error_line(capsys).startswith("error: graph 'knn:1': with --sequence the graph is "
                                          "the robots' communication graph")
