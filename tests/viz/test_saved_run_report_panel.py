"""viz.saved_run's report panel of a run-images folder says what the run's own panel says."""

from __future__ import annotations

import json

from rerun.chunk import RrdReader
from test_rerun_log import make_record
from test_saved_run import _photo_report, _save

from viz.saved_run import main


def _summary(registered: int, points: int) -> dict:
    """A reconstruction's figures as run-images writes them (``MappingSummary.summary()``)."""
    return {"images": 3, "models": 1, "registered_images": registered,
            "registered_names": [f"cam{i:02d}" for i in range(registered)], "points": points,
            "observations": 3 * points, "mean_track_length": 3.0,
            "mean_reprojection_error": 0.25, "min_pose_inliers": 30}


def _report_text(path) -> str:
    chunks = RrdReader(path).store().stream().filter(content="/report").to_chunks()
    return next(c.to_record_batch().column("TextDocument:text").to_pylist()[-1][0]
                for c in chunks if c.entity_path == "/report")


def test_the_report_panel_of_a_photo_run_shows_its_reconstructions_and_warnings(tmp_path):
    """The run's panel shows the reconstructions before and after cleaning and the
    warnings (flags) of its report.json; the recording written from the folder left both
    out, though report.json holds them."""
    record = make_record()
    folder = _save(record, tmp_path / "run")
    report = _photo_report(record)
    report["triangulation"] = {"before": _summary(3, 847), "after": _summary(2, 810)}
    report["flags"] = [{"flag": "unregistered", "message": "1 of 3 images left unregistered",
                        "likely_cause": "too few matches"}]
    (folder / "report.json").write_text(json.dumps(report))
    assert main([str(folder)]) == 0
    text = _report_text(folder / "recording.rrd")
    assert "| Reconstruction | before | after |" in text, text
    assert "| Registered images | 3 | 2 |" in text and "| Points | 847 | 810 |" in text
    assert "**unregistered**: 1 of 3 images left unregistered. Likely cause: too few " \
           "matches." in text
