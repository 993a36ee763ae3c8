"""Reading hloc's matches shows a progress bar of the pairs read on a terminal (as the other
long stages do), and nothing with --quiet or off a terminal."""

import io
import logging

import numpy as np
from hloc_files import first_matched, write_h5

import pipeline.progress as progress
from pipeline.inputs.hloc import read_h5


def _terminal():
    f = io.StringIO()
    f.isatty = lambda: True
    return f


def test_reading_matches_draws_a_bar_on_a_terminal_only(tmp_path, monkeypatch):
    feats, matches = write_h5(tmp_path, ["a.jpg", "b.jpg", "c.jpg"], 6,
                              lambda k: first_matched(6, 4))
    level = progress.log.level
    try:
        progress.log.setLevel(logging.INFO)
        term = _terminal()
        monkeypatch.setattr(progress.sys, "stderr", term)
        contents = read_h5(feats, matches)
        assert len(contents.links) == 12
        assert "reading matches" in term.getvalue()
        plain = io.StringIO()  # not a terminal
        monkeypatch.setattr(progress.sys, "stderr", plain)
        read_h5(feats, matches)
        assert plain.getvalue() == ""
        progress.log.setLevel(logging.WARNING)  # --quiet
        quiet = _terminal()
        monkeypatch.setattr(progress.sys, "stderr", quiet)
        read_h5(feats, matches)
        assert quiet.getvalue() == ""
    finally:
        progress.log.setLevel(level)
    assert np.array_equal(contents.features_per_camera, [6, 6, 6])
