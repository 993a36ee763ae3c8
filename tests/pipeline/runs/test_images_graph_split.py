"""run-images warns, before any work, when its comm graph leaves images in groups that never
match each other (as --sequence and run-landmarks do)."""

import numpy as np
import pytest
from PIL import Image

from pipeline.progress import StageTimer
from pipeline.runs.images import ImagesConfig, _load


def _photos(tmp_path, names):
    d = tmp_path / "photos"
    d.mkdir()
    for k, name in enumerate(names):
        rng = np.random.default_rng(k)
        Image.fromarray((rng.random((40, 50, 3)) * 255).astype(np.uint8)).save(d / name)
    return d


def _split_warnings(caplog):
    return [r.getMessage() for r in caplog.records if "splits the" in r.getMessage()]


def test_a_graph_file_that_splits_the_images_is_warned(tmp_path, caplog):
    """A graph file joining a-b and c-d left two groups without a word: the reconstruction
    then held one of them."""
    d = _photos(tmp_path, ["a.png", "b.png", "c.png", "d.png"])
    graph = tmp_path / "g.csv"
    graph.write_text("a.png,b.png\nc.png,d.png\n")
    with caplog.at_level("WARNING", logger="pipeline"):
        _, edges = _load(ImagesConfig(directory=str(d), graph=str(graph)), StageTimer())
    assert len(edges) == 2
    assert _split_warnings(caplog) == [
        "warning: the comm graph splits the 4 images into 2 groups that never match each "
        "other: their features cannot be associated across the groups (choose a denser "
        "--graph)"]


@pytest.mark.parametrize("graph", ["ring", "line", "complete"])
def test_a_connected_graph_is_not_warned(tmp_path, caplog, graph):
    d = _photos(tmp_path, ["a.png", "b.png", "c.png", "d.png"])
    with caplog.at_level("WARNING", logger="pipeline"):
        _load(ImagesConfig(directory=str(d), graph=graph), StageTimer())
    assert _split_warnings(caplog) == []
