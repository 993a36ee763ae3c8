"""pipeline.inputs.hloc: a dataset at the root of features.h5 / matches.h5 belongs to no image
or pair; it is refused by where it is, not read as an image named ''."""

import h5py
import numpy as np
import pytest
from hloc_files import first_matched, run_clean_h5, write_h5

NAMES = ["a.jpg", "b.jpg", "c.jpg"]
M = 12


def _write(d):
    return write_h5(d, NAMES, M, lambda k: first_matched(M, 8))


def _add(path, name, data):
    with h5py.File(path, "a") as fd:
        fd.create_dataset(name, data=data)


def test_the_files_as_written_are_read(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    code, captured, _ = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 0 and captured.out.startswith("3 images, 3 image pairs, 24 matches")


@pytest.mark.parametrize("only", [False, True], ids=["beside-groups", "alone"])
def test_root_keypoints_are_refused_not_read_as_an_image_named_empty(tmp_path, capsys, only):
    feats, matches = _write(tmp_path)
    if only:
        feats.unlink()
        with h5py.File(feats, "w"):
            pass
    _add(feats, "keypoints", np.zeros((5, 2), np.float32))
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {feats}: a 'keypoints' dataset at the file's root group ('/') belongs to no "
        "image: hloc's features.h5 holds one group per image, named after it, with the image's "
        "'keypoints'; write the keypoints so, or remove the dataset")


def test_root_matches0_is_refused_by_where_it_is(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    _add(matches, "matches0", np.full(M, -1, np.int32))
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists()
    assert "a 'matches0' dataset at the file's root group ('/') belongs to no image pair" in \
        captured.err and "pair group ''" not in captured.err


def test_other_root_datasets_are_named_as_the_root_not_as_group_empty(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    _add(matches, "info", np.arange(3))
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists()
    err = captured.err.strip().splitlines()[-1]
    assert err.startswith(f"error: {matches}: the file's root group ('/') holds 'info' but no "
                          "'matches0'") and err.endswith("or remove those datasets")
