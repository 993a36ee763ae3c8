"""The ``cuts`` panel says which links the 3D views cannot draw: those touching an image
without a pose (a photograph the mapper did not register), and every link when no image has
one."""

import re

import numpy as np
from test_rerun_log import make_record

from viz.recording_reader import count_strips
from viz.rerun_log import cut_summary, log_run


def test_links_to_an_image_without_a_pose_are_said_not_drawn(tmp_path):
    """The panel said 'The first 3D view shows the cut links' and counted every cut link,
    while the 3D view left out those touching an unregistered image: the counts disagreed
    with nothing to say why."""
    record = make_record()
    record.views[2].R = record.views[2].t = None  # not registered
    lk, deleted = record.ledger.links, record.ledger.status == "deleted"
    touch = (lk.cam_i == 2) | (lk.cam_j == 2)
    assert (touch & deleted).any() and (touch & ~deleted).any()  # the case of this test
    path = log_run(tmp_path / "recording.rrd", record)
    drawn = count_strips(path, "world/links/deleted")
    assert drawn == int((deleted & ~touch).sum()) < int(deleted.sum())
    text = cut_summary(record)
    said = re.search(r"(\d+) links? cut and (\d+) links? kept touch an image without a pose",
                     text)
    assert said is not None, text
    assert int(said[1]) + drawn == int(deleted.sum())
    assert int(said[2]) + count_strips(path, "world/links/kept") == int((~deleted).sum())


def test_without_any_pose_the_panel_does_not_point_at_a_3d_view_of_links():
    record = make_record(posed=False)
    text = cut_summary(record)
    assert "The first 3D view shows the cut links" not in text, text
    assert "No image has a pose, so no link is drawn in 3D" in text
    assert np.isin(["kept", "deleted"], record.ledger.status).all()
