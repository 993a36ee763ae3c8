"""The default run folder of run-landmarks (LandmarksConfig.out_dir)."""

from pathlib import Path

from pipeline.runs.landmarks import LandmarksConfig


def test_a_graph_file_names_the_default_run_folder_by_its_stem(tmp_path):
    """--graph FILE without --out: the folder was runs/landmarks-DIR-<the file's path>, which
    nested folders (runs/landmarks-hotel-/tmp/x/g.csv/) and, with '..' in the path, put the run
    outside runs/."""
    graph = tmp_path / "sub" / "edges.csv"
    graph.parent.mkdir()
    graph.write_text("0,1\n")
    for given in (str(graph), str(tmp_path / "sub" / ".." / "sub" / "edges.csv")):
        out = LandmarksConfig(directory=str(tmp_path / "hotel"), graph=given).out_dir()
        assert out == Path("runs") / "landmarks-hotel-edges"


def test_a_graph_kind_names_the_default_run_folder():
    assert LandmarksConfig(directory="data/hotel", graph="seq:4", frames=20).out_dir() == \
        Path("runs") / "landmarks-hotel-f20-seq4"
