"""A MAT v5 keypoint file with one damaged byte where an array's numbers begin (a data type
that is no MAT data type) is refused naming the file: run-landmarks died of a segmentation
fault inside SciPy's MAT reader, with no message at all."""

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from PIL import Image

sys.path.insert(0, str(Path(__file__).parents[1] / "commands"))
from hostile import run_capped  # noqa: E402

KP = {"a": [[10.0, 10.0], [50.0, 50.0], [80.0, 20.0]], "b": [[12.0, 11.0], [52.0, 49.0],
                                                             [79.0, 22.0]],
      "c": [[9.0, 12.0], [48.0, 51.0], [81.0, 21.0]]}


@pytest.mark.parametrize("mdtype", [0, 14, 19, 0x80])
def test_a_mat_file_with_a_damaged_data_type_is_named(tmp_path, mdtype):
    folder = tmp_path / "set"
    folder.mkdir()
    for name, kp in KP.items():
        Image.new("L", (100, 100), 128).save(folder / f"{name}.png")
        scipy.io.savemat(folder / f"{name}.mat", {"pts_coord": np.asarray(kp).T})
    data = bytearray((folder / "b.mat").read_bytes())
    at = data.index(b"\x09\x00\x00\x00\x30\x00\x00\x00")  # miDOUBLE, 48 bytes: the numbers
    data[at] = mdtype
    (folder / "b.mat").write_bytes(bytes(data))
    r = run_capped(["run-landmarks", folder, "--graph", "complete", "--out", tmp_path / "run"])
    assert r.returncode == 2, (r.returncode, r.stderr[-1500:])
    assert "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines()[-1] == (
        f"error: {folder / 'b.mat'}: a damaged MAT file (a data element of type {mdtype}, which "
        "is no MAT data type here); save it again from MATLAB or SciPy (pts_coord a numeric "
        "2 x K array), or remove it")
    assert not (tmp_path / "run").exists()
