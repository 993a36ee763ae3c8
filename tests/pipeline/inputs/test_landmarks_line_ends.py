"""Label tables of a labelled-landmark folder with every line end a text editor writes: LF,
CRLF, and a carriage return alone (classic Mac OS), as the descriptor tables beside them."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder

PTS = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0], [20.0, 35.0]])


def _image(path: Path, size=(64, 48)) -> None:
    rng = np.random.default_rng(len(path.name))
    Image.fromarray(rng.integers(0, 255, size[::-1], dtype=np.uint8)).save(path)


def _folder(tmp_path: Path, end: str, rows=None) -> Path:
    for k in range(3):
        _image(tmp_path / f"view{k}.png")
        lines = rows if (rows is not None and k == 1) else \
            [f"{x:g} {y:g}" for x, y in PTS + k]
        (tmp_path / f"view{k}.txt").write_bytes((end.join(lines) + end).encode())
        desc = np.abs(np.random.default_rng(k).normal(size=(len(PTS), 5)))
        (tmp_path / f"view{k}.scf").write_bytes(
            (end.join(" ".join(f"{v:.4f}" for v in r) for r in desc) + end).encode())
    return tmp_path


@pytest.mark.parametrize("end", ["\n", "\r\n", "\r"])
def test_label_tables_are_read_with_any_line_end(tmp_path, end):
    frames = load_landmark_folder(_folder(tmp_path, end))
    assert [f.keypoint_file for f in frames] == ["view0.txt", "view1.txt", "view2.txt"]
    for k, fr in enumerate(frames):
        np.testing.assert_allclose(fr.keypoints, PTS + k)
        assert fr.descriptors.shape == (len(PTS), 5)


def test_a_bad_row_behind_carriage_returns_is_named_by_its_line(tmp_path):
    rows = ["11 13", "31 21", "1 2 3", "21 36"]
    with pytest.raises(InputError, match=r"view1.txt: not a keypoint table \(line 3 is '1 2 3' "
                                         r"\(3 numbers\)"):
        load_landmark_folder(_folder(tmp_path, "\r", rows))
