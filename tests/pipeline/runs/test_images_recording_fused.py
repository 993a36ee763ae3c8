"""run-images: fused points that cannot be put into the frame of the drawn reconstruction
are left out of the recording with a warning naming why."""

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline import colmap
from pipeline.runs import images


@pytest.mark.parametrize("before,after,why", [
    ({"a": 0, "b": 0}, {"a": 0, "b": 0, "c": 0}, "only 2 images are registered both"),
    ({"a": 0, "b": 0, "c": 0}, {"a": 0, "b": 0, "c": 0}, "are collinear"),
])
def test_fused_points_left_out_are_named(monkeypatch, before, after, why):
    import viz.rerun_log

    recorded = []
    monkeypatch.setattr(colmap, "similarity_between", lambda src, tgt: None)
    monkeypatch.setattr(colmap, "registered_poses", lambda rec: rec)
    monkeypatch.setattr(images, "_points_and_tracks",
                        lambda *a: (np.zeros((0, 3)), np.zeros(0, int), None))
    monkeypatch.setattr(viz.rerun_log, "log_run",
                        lambda path, record, live=None: recorded.append(record))
    cleaning = SimpleNamespace(fused_points=np.zeros((7, 3)), ledger=None)
    warnings = []
    images._write_recording("x.rrd", [], [], cleaning, SimpleNamespace(reconstruction=before),
                            SimpleNamespace(reconstruction=after), None, "",
                            warn=warnings.append)
    assert recorded[0].fused_points is None
    assert len(warnings) == 1
    assert warnings[0].startswith("the 7 fused points (report.json fusion.fused_points) "
                                  "are not in the recording")
    assert why in warnings[0]
