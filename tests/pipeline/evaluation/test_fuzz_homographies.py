"""Fuzzed homography files of ``--truth homographies`` (``H1to{k}p``): a damaged file gives
an invertible finite homography or an InputError naming the file."""

import sys
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pipeline.evaluation.truth import read_homographies

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, read_or_refuse, text_mutant  # noqa: E402

# the Graffiti set's H1to2p and a hand-written one
VALID = ["8.7976964e-01   3.1245438e-01  -3.9430589e+01\n"
         "-1.8389418e-01   9.3847198e-01   1.5315784e+02\n"
         "1.9641425e-04  -1.6015275e-05   1.0000000e+00\n",
         "1 0 5\n0 1 -3\n0 0 1\n"]


@FUZZ
@given(st.one_of(st.sampled_from(VALID).flatmap(text_mutant).map(
    lambda s: s.encode("utf-8", "surrogatepass")), bytes_mutant(VALID[0].encode())))
def test_a_damaged_homography_file_is_read_or_refused(content):
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "H1to2p.txt").write_bytes(content)
        H = read_or_refuse(lambda: read_homographies(d, 2), "H1to2p")
        if H is not None:
            assert H.shape == (2, 3, 3) and np.isfinite(H).all()
            assert np.isfinite(np.linalg.inv(H[1])).all()
