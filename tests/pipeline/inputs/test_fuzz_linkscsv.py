"""Fuzzed links files (``resolve --links``, a links team's files): every damaged file is read
to valid links or refused with an InputError naming the file, and the fast reader of plain
files gives what the row reader gives."""

import sys
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pipeline.inputs import linkscsv

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, read_or_refuse, text_mutant  # noqa: E402

VALID = ["cam_i,feat_i,cam_j,feat_j,quality\n0,0,1,0,0.9\n0,1,2,0,0.5\n1,0,2,1,1\n1,1,2,0,0.25\n",
         "0,0,1,0\n0,1,2,0\n1,0,2,1\n1,1,2,0\n",
         "cam_i,feat_i,cam_j,feat_j,status,reason,round,truth\n0,0,1,0,kept,,,1\n"
         "0,1,2,0,deleted,cycle,3,0\n1,0,2,1,kept,,2,\n"]


def _check(lf) -> None:
    lk = lf.links
    n = lk.cam_i.size
    assert all(a.shape == (n,) for a in (lk.feat_i, lk.cam_j, lk.feat_j, lf.line))
    assert (lk.cam_i < lk.cam_j).all() and (lk.feat_i >= 0).all() and (lk.feat_j >= 0).all()
    if lf.has_quality:
        assert np.isfinite(lk.quality).all()


def _row_reader(path):
    real = linkscsv._read_plain
    linkscsv._read_plain = lambda p: None
    try:
        return linkscsv.read_links_csv(path)
    finally:
        linkscsv._read_plain = real


@FUZZ
@given(st.sampled_from(VALID).flatmap(text_mutant))
def test_a_damaged_links_file_is_read_or_refused(text):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "links.csv"
        path.write_bytes(text.encode("utf-8", "surrogatepass"))
        lf = read_or_refuse(lambda: linkscsv.read_links_csv(path), str(path))
        if lf is None:
            return
        _check(lf)
        rows = _row_reader(path)
        for name in ("cam_i", "feat_i", "cam_j", "feat_j", "quality"):
            assert np.array_equal(getattr(lf.links, name), getattr(rows.links, name)), name
        assert np.array_equal(lf.line, rows.line) and lf.has_quality == rows.has_quality
