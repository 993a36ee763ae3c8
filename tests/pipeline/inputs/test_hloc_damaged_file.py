"""A features.h5 or matches.h5 damaged inside (an object header or B-tree overwritten, a
file HDF5 still opens) is refused by ``clean-h5`` in one line naming the file: it ended in a
RuntimeError or KeyError traceback from h5py."""

import h5py
import numpy as np
import pytest
from hloc_files import first_matched, run_clean_h5, write_h5


@pytest.mark.parametrize("which", ["features", "matches"])
@pytest.mark.parametrize("signature", [b"TREE", b"SNOD", b"HEAP"])
def test_a_file_damaged_inside_is_named(tmp_path, capsys, which, signature):
    feats, matches = write_h5(tmp_path, ["a.jpg", "b.jpg", "c.jpg"], 6,
                              lambda k: first_matched(6, 4))
    path = feats if which == "features" else matches
    data = bytearray(path.read_bytes())
    data[data.index(signature)] = 0  # the first of them: the root group's
    path.write_bytes(bytes(data))
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err, captured.err
    assert captured.err.strip().splitlines()[-1].startswith(
        f"error: {which} file {str(path)!r} is damaged: HDF5 cannot read it")


def test_a_group_name_that_is_not_utf8_is_named(tmp_path, capsys):
    feats, matches = write_h5(tmp_path, ["a.jpg", "b.jpg", "c.jpg"], 6,
                              lambda k: first_matched(6, 4))
    with h5py.File(feats, "a") as fd:
        fd.create_group(b"d\xff.jpg").create_dataset("keypoints", data=np.zeros((6, 2), "f4"))
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err, captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {feats}: the name b'd\\xff.jpg' is not UTF-8 text; hloc names its groups "
        "after the images, in UTF-8: rename that group or dataset (or its image, and extract "
        "or match again)")
