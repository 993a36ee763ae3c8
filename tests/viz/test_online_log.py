"""Tests of viz.online_log: the step timeline of an online run, read back."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from rerun.chunk import RrdReader

from viz.online_log import log_online


def _texts(path, entity):
    out = []
    for chunk in RrdReader(path).store().stream().filter(content=entity).to_chunks():
        if chunk.entity_path == entity:
            d = chunk.to_record_batch().to_pydict()
            out += [t for row in d["TextLog:text"] for t in row]
    return out


def _scalars(path, entity):
    """``{step: value}`` of a ``steps/<name>`` scalar."""
    out = {}
    for chunk in RrdReader(path).store().stream().filter(content=entity).to_chunks():
        if chunk.entity_path == entity:
            d = chunk.to_record_batch().to_pydict()
            for s, row in zip(d["step"], d["Scalars:scalars"], strict=True):
                out[int(s)] = float(row[0])
    return out


def _cut_labels(path):
    """Links drawn cut at each step: the sum of the strips' ``N links`` labels."""
    per_step = {}
    for chunk in RrdReader(path).store().stream().filter(content="/world/links/cut").to_chunks():
        if chunk.entity_path != "/world/links/cut":
            continue
        d = chunk.to_record_batch().to_pydict()
        for s, labels in zip(d["step"], d.get("LineStrips3D:labels", [None] * len(d["step"])),
                             strict=True):
            per_step[int(s)] = sum(int(x.split()[0]) for x in labels or [])
    return per_step


def test_the_step_log_counts_every_link_the_step_draws_cut(tmp_path):
    """A step whose fusion cut links draws them in world/links/cut; its log line says so,
    not only the consistency stage's cuts (it read '1 cut' beside 3 links drawn cut)."""
    # frames 0..3: two robots, two steps; links between the frames of each step
    online = SimpleNamespace(step=np.array([0, 0, 1, 1]), robot=np.array([0, 1, 0, 1]))
    online.links = SimpleNamespace(ci=np.array([0, 0, 2, 2, 2, 2]), cj=np.array([1, 1, 3, 3, 3, 3]),
                                   step_added=np.array([0, 0, 1, 1, 1, 1]),
                                   step_cut=np.array([-1, -1, 1, 1, 1, -1]))
    steps = [dict(step=0, links_new=2, conflictive_features=0, cut=0, cut_history=0,
                  conflictive_sets_after=0, rounds=1, bytes=10, fusion={"cut": 0}),
             dict(step=1, links_new=4, conflictive_features=2, cut=1, cut_history=0,
                  conflictive_sets_after=0, rounds=2, bytes=20, fusion={"cut": 2})]
    centres = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    path = log_online(tmp_path / "recording.rrd", None, online, steps, centres=centres)
    assert _cut_labels(path)[1] == 3
    line = _texts(path, "/steps/log")[1]
    assert "1 cut (0 by the history check), 2 cut by fusion" in line
    # the plots name both stages' cuts, which add up to the links drawn cut
    assert _scalars(path, "/steps/cut") == {0: 0.0, 1: 1.0}
    assert _scalars(path, "/steps/cut_fusion") == {0: 0.0, 1: 2.0}
    # without fusion (--no-fusion, photographs) the line names none
    for r in steps:
        del r["fusion"]
    path = log_online(tmp_path / "nofusion.rrd", None, online, steps, centres=centres)
    assert "fusion" not in _texts(path, "/steps/log")[1]


def test_a_failed_recording_leaves_the_previous_one_and_no_temp_file(tmp_path):
    online = SimpleNamespace(step=np.array([0, 0]), robot=np.array([0, 1]))
    online.links = SimpleNamespace(ci=np.array([0]), cj=np.array([1]),
                                   step_added=np.array([0]), step_cut=np.array([-1]))
    path = tmp_path / "recording.rrd"
    path.write_bytes(b"previous")
    with pytest.raises(KeyError):  # a step record without its figures
        log_online(path, None, online, [dict(step=0)], centres=np.zeros((2, 3)))
    assert path.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.rrd"]
