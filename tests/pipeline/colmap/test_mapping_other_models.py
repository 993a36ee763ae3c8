"""pipeline.colmap.mapping: the images of the models COLMAP made beside the largest are kept in
the summary (``other_models``), which ``sparse/`` does not hold; they were dropped unsaid."""

from types import SimpleNamespace

from pipeline.colmap.mapping import MappingSummary, _largest, _others


class _Model:
    def __init__(self, names, points=10):
        self.images = {i + 1: SimpleNamespace(name=n) for i, n in enumerate(names)}
        self.points = points

    def reg_image_ids(self):
        return list(self.images)

    def num_reg_images(self):
        return len(self.images)

    def num_points3D(self):  # noqa: N802 - pycolmap's name
        return self.points


def test_the_other_models_are_listed_largest_first():
    models = {0: _Model(["c.jpg", "d.jpg"]), 1: _Model(["a.jpg", "b.jpg", "e.jpg"]),
              2: _Model(["f.jpg"]), 3: _Model([])}
    largest = _largest(models)
    assert sorted(im.name for im in largest.images.values()) == ["a.jpg", "b.jpg", "e.jpg"]
    assert _others(models, largest) == [["c.jpg", "d.jpg"], ["f.jpg"]]
    assert _others({0: largest}, largest) == []


def test_the_summary_says_other_models_only_when_there_are_some():
    s = MappingSummary(3, 1, 3, ["a", "b", "c"], 10, 30, 3.0, 0.5)
    assert "other_models" not in s.summary()
    s.other_models = [["d", "e"]]
    assert s.summary()["other_models"] == [["d", "e"]]
