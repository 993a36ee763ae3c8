"""A reconstruction without a point has no mean track length or reprojection error: the report
says so (None, '–' in the table) instead of a perfect 0 px."""

import numpy as np

from pipeline.colmap import MappingSummary
from pipeline.evaluation.flags import reconstruction_flags
from pipeline.evaluation.report import mapping_markdown


def _empty(n: int = 2) -> MappingSummary:
    # what a mapping that started no model gives (two photos from one place, blank images)
    return MappingSummary(n, 0, 0, [], 0, 0, 0.0, 0.0)


def _model(n: int = 2) -> MappingSummary:
    return MappingSummary(n, 1, n, [f"{k}.png" for k in range(n)], 50, 150, 3.0, 0.4)


def test_a_model_without_points_has_no_means():
    s = _empty().summary()
    assert s["points"] == 0
    assert s["mean_track_length"] is None and s["mean_reprojection_error"] is None
    kept = _model().summary()
    assert kept["mean_track_length"] == 3.0 and kept["mean_reprojection_error"] == 0.4


def test_the_table_prints_no_figure_for_them():
    md = mapping_markdown(_empty(), _model())
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:4]]
            for line in md.splitlines() if line.startswith("| ")}
    assert rows["Mean reprojection error [px]"] == ["–", "0.4"]
    assert rows["Mean track length"] == ["–", "3.0"]
    assert rows["Points"] == ["0", "50"]


def test_flags_read_the_missing_means():
    edges = np.array([[0, 1]])
    empty, model = _empty().summary(), _model().summary()
    flags = reconstruction_flags(2, empty, empty, edges, [193], [300, 300])
    assert [f["flag"] for f in flags] == ["few-registered"]
    # a model lost by cleaning: fewer points, said once
    flags = reconstruction_flags(2, model, empty, edges, [193], [300, 300])
    assert "cleaning-worse" in [f["flag"] for f in flags]
