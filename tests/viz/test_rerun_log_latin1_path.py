"""Recordings written where a folder or the file's own name is not UTF-8 (Latin-1 bytes):
Rerun takes a path as UTF-8 text, so run-formation, run-formations, clean-db and clean-h5
did their whole work and then ended in a UnicodeEncodeError traceback, nothing written."""

import os
import shutil
from types import SimpleNamespace

import numpy as np
from test_rerun_log import make_record

from viz.online_log import log_online
from viz.recording_reader import count_strips
from viz.rerun_log import log_run


def _readable_copy(path, tmp_path):
    """A copy under a UTF-8 name (Rerun's reader takes one too)."""
    copy = tmp_path / "copy.rrd"
    shutil.copyfile(path, copy)
    return copy


def test_a_run_recording_in_a_latin1_folder_under_a_latin1_name(tmp_path):
    folder = tmp_path / os.fsdecode(b"caf\xe9")
    record = make_record()
    path = log_run(folder / os.fsdecode(b"r\xe9sum\xe9.rrd"), record)
    assert os.listdir(os.fsencode(folder)) == [b"r\xe9sum\xe9.rrd"]  # no temporary file left
    deleted = int((record.ledger.status == "deleted").sum())
    assert count_strips(_readable_copy(path, tmp_path), "world/links/deleted") == deleted


def test_an_online_recording_in_a_latin1_folder(tmp_path):
    online = SimpleNamespace(step=np.array([0, 0]), robot=np.array([0, 1]))
    online.links = SimpleNamespace(ci=np.array([0]), cj=np.array([1]),
                                   step_added=np.array([0]), step_cut=np.array([-1]))
    steps = [dict(step=0, links_new=1, conflictive_features=0, cut=0, cut_history=0,
                  conflictive_sets_after=0, rounds=1, bytes=10)]
    folder = tmp_path / os.fsdecode(b"\xe9t\xe9")
    folder.mkdir()
    path = log_online(folder / "recording.rrd", None, online, steps, centres=np.zeros((2, 3)))
    assert os.listdir(os.fsencode(folder)) == [b"recording.rrd"]
    assert _readable_copy(path, tmp_path).stat().st_size > 0
