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


def test_votes_that_remove_every_match_are_named_in_the_warning(tmp_path):
    """Three images of two landmarks whose Hungarian matches form one inconsistent cycle
    (a-b swapped, a-c and b-c not): every pair's two-hop vote ties with its direct one, so
    the votes keep no match. The no-links warning blamed a --ratio gate or the --graph,
    neither of which this run has; it now names the votes and the 6 matches they removed."""
    import numpy as np
    from PIL import Image

    from pipeline.runs.landmarks import run_landmarks

    desc = {"a": [[-2, 1], [0, 2]], "b": [[1, 2], [1, -1]], "c": [[-2, 0], [1, -1]]}
    for name, d in desc.items():
        Image.new("L", (100, 100), 128).save(tmp_path / f"{name}.png")
        np.savetxt(tmp_path / f"{name}.txt", [[10.0, 10.0], [50.0, 50.0]])
        np.savetxt(tmp_path / f"{name}.scf", np.asarray(d, dtype=float))
    config = LandmarksConfig(directory=str(tmp_path), geometry="none", resolution="paper",
                             baselines=False, out=str(tmp_path / "run"))
    _, report = run_landmarks(config)
    assert report["pairwise"]["input_links"]["predicted_pairs"] == 6
    assert report["before"]["links"] == 0
    [warning] = report["warnings"]
    assert warning["code"] == "no-links"
    assert "--refine votes step removed all 6 matches" in warning["message"]
    assert "--ratio" not in warning["message"]
