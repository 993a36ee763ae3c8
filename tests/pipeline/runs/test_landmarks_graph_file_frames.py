"""run-landmarks --graph FILE with --frames N: the file's indices count the folder's images in
name order, as its names do and as without --frames; an edge joining an image --frames leaves
out is refused, naming it. The indices counted the kept images instead: '0,1' with --frames 3
of six images joined images 0 and 2, while 'v0.png,v1.png' was refused, and a file mixing
names and indices meant two different numberings at once."""

import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.runs.landmarks import LandmarksConfig, landmark_comm_graph, run_landmarks

FOLDER = [f"v{k}.png" for k in range(6)]


KEPT = ["v0.png", "v2.png", "v4.png"]  # --frames 3 of six: stride 2 from the first


@pytest.mark.parametrize("text", ["0,2\n2,4\n", "v0.png,v2.png\nv2.png,v4.png\n",
                                  "v0.png,2\n4,v2.png\n"])
def test_indices_and_names_of_a_graph_file_count_the_folder_images(tmp_path, text):
    graph = tmp_path / "edges.csv"
    graph.write_text(text)
    edges = landmark_comm_graph(str(graph), KEPT, FOLDER, 3)
    assert edges.tolist() == [[0, 1], [1, 2]]  # v0 - v2, v2 - v4 in the kept images' order


@pytest.mark.parametrize("text", ["0,1\n", "v0.png,v1.png\n", "v2.png,5\n"])
def test_an_edge_to_an_image_frames_leaves_out_is_refused(tmp_path, text):
    graph = tmp_path / "edges.csv"
    graph.write_text(text)
    with pytest.raises(InputError, match=r"edges.csv: the edge v\d.png - v\d.png \(images \d and "
                                         r"\d of the folder's 6, in name order\) joins "
                                         r"v[15].png, which --frames 3 leaves out \(it keeps "
                                         r"images 0, 2, 4\)"):
        landmark_comm_graph(str(graph), KEPT, FOLDER, 3)


def test_kinds_are_built_over_the_kept_images(tmp_path):
    assert landmark_comm_graph("ring", KEPT, FOLDER, 3).tolist() == [[0, 1], [0, 2], [1, 2]]
    assert landmark_comm_graph("seq:1", KEPT, FOLDER, 3).tolist() == [[0, 1], [1, 2]]


def test_a_run_with_frames_reads_the_file_by_folder_index(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    rng = np.random.default_rng(0)
    pts = rng.uniform(5, 35, (6, 2))
    for k in range(6):
        Image.new("L", (64, 48), 128).save(data / f"v{k}.png")
        np.savetxt(data / f"v{k}.txt", pts + k)
        np.savetxt(data / f"v{k}.scf", np.eye(6) + 0.01 * k)
    graph = tmp_path / "edges.csv"
    graph.write_text("0,2\n2,4\n")  # images v0 - v2 - v4; indices 3 and 4 are no kept image
    config = LandmarksConfig(directory=str(data), graph=str(graph), frames=3, geometry="none",
                             baselines=False, out=str(tmp_path / "run"))
    _, report = run_landmarks(config)
    assert report["images"] == KEPT
    assert report["comm_edges"] == [[0, 1], [1, 2]]
