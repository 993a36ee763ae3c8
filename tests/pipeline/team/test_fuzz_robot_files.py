"""Fuzzed files of a links team's robot (``robot --team``: its ``data.keypoints`` and
``data.weights`` files): every damaged file is read to valid values or refused with an
InputError naming the file."""

import json
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.team.robot import links_camera, links_weights
from pipeline.team.teamfile import load_team

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, read_or_refuse, text_mutant  # noqa: E402

_CAM = {"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "t": [0.0, 0.0, 1.5]}
KEYPOINTS = "x,y\n10.5,20.25\n3,4\n100,0.125\n"
WEIGHTS = "weight\n0.5\n-1.25\ninf\n"


def _team(folder: Path):
    doc = {"version": 1, "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"}
                                    for i in range(2)],
           "comm_edges": [[0, 1]],
           "data": {"kind": "links", "links": ["l0.csv", "l1.csv"], "features_per_camera": [3, 3],
                    "keypoints": ["k0.csv", "k1.csv"], "cameras": [_CAM, _CAM],
                    "weights": ["w0.csv", "w1.csv"]}}
    (folder / "TEAM.json").write_text(json.dumps(doc))
    return load_team(folder / "TEAM.json")


CONTENT = st.one_of(text_mutant(KEYPOINTS).map(lambda s: s.encode("utf-8", "surrogatepass")),
                    bytes_mutant(KEYPOINTS.encode()))


@FUZZ
@given(CONTENT)
def test_a_damaged_keypoints_file_is_read_or_refused(content):
    with tempfile.TemporaryDirectory() as d:
        team = _team(Path(d))
        path = Path(d) / "k0.csv"
        path.write_bytes(content)
        out = read_or_refuse(lambda: links_camera(team, 0), str(path))
        if out is not None:
            kp = out[0]
            assert kp.shape == (3, 2) and np.isfinite(kp).all()
            # numbers as a CSV writes them: digits 0-9 (Python's float() also reads "1_0"
            # as 10, other scripts' digits and "infinity")
            assert re.fullmatch(r"[0-9eE+.,\s-]*", content.decode("utf-8-sig").split("\n", 1)[1]), content


@FUZZ
@given(st.one_of(text_mutant(WEIGHTS).map(lambda s: s.encode("utf-8", "surrogatepass")),
                 bytes_mutant(WEIGHTS.encode())))
def test_a_damaged_weights_file_is_read_or_refused(content):
    with tempfile.TemporaryDirectory() as d:
        team = _team(Path(d))
        path = Path(d) / "w0.csv"
        path.write_bytes(content)
        w = read_or_refuse(lambda: links_weights(team, 0, 3), str(path))
        if w is not None:
            assert w.shape == (3,) and not np.isnan(w).any()


@pytest.mark.parametrize("row, why", [(b"1_0,2", "1_0"), ("\u0661,2".encode(), "\u0661"),
                                      (b"\xff1,2", "not a UTF-8 text file")])
def test_a_keypoint_not_written_in_digits_is_refused(tmp_path, row, why):
    team = _team(tmp_path)
    (tmp_path / "k0.csv").write_bytes(b"x,y\n3,4\n" + row + b"\n5,6\n")
    with pytest.raises(InputError, match=re.escape(why)) as exc:
        links_camera(team, 0)
    assert str(tmp_path / "k0.csv") in str(exc.value)
