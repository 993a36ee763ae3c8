"""pipeline.inputs.hloc: a dataset at the root of features.h5 / matches.h5 belongs to no image
or pair; it is refused by where it is, not read as an image named ''."""

import h5py
import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair

NAMES = ["a.jpg", "b.jpg", "c.jpg"]
M = 12


def _write(d):
    feats, matches = d / "features.h5", d / "matches.h5"
    rng = np.random.default_rng(0)
    with h5py.File(feats, "w") as fd:
        for name in NAMES:
            fd.create_group(name).create_dataset(
                "keypoints", data=rng.uniform(0, 100, (M, 2)).astype(np.float32))
    with h5py.File(matches, "w") as fd:
        for i, j in ((0, 1), (1, 2), (0, 2)):
            m0 = np.full(M, -1, np.int32)
            m0[:8] = np.arange(8)
            fd.create_group(names_to_pair(NAMES[i], NAMES[j])).create_dataset("matches0", data=m0)
    return feats, matches


def _add(path, name, data):
    with h5py.File(path, "a") as fd:
        fd.create_dataset(name, data=data)


def _run(capsys, tmp_path, feats, matches):
    out = tmp_path / "out.h5"
    code = main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--out", str(out), "--no-rerun"])
    captured = capsys.readouterr()
    return code, captured, out


def test_the_files_as_written_are_read(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    code, captured, _ = _run(capsys, tmp_path, feats, matches)
    assert code == 0 and captured.out.startswith("3 images, 3 image pairs, 24 matches")


@pytest.mark.parametrize("only", [False, True], ids=["beside-groups", "alone"])
def test_root_keypoints_are_refused_not_read_as_an_image_named_empty(tmp_path, capsys, only):
    feats, matches = _write(tmp_path)
    if only:
        feats.unlink()
        with h5py.File(feats, "w"):
            pass
    _add(feats, "keypoints", np.zeros((5, 2), np.float32))
    code, captured, out = _run(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {feats}: a 'keypoints' dataset at the file's root group ('/') belongs to no "
        "image: hloc's features.h5 holds one group per image, named after it, with the image's "
        "'keypoints'; write the keypoints so, or remove the dataset")


def test_root_matches0_is_refused_by_where_it_is(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    _add(matches, "matches0", np.full(M, -1, np.int32))
    code, captured, out = _run(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists()
    assert "a 'matches0' dataset at the file's root group ('/') belongs to no image pair" in \
        captured.err and "pair group ''" not in captured.err


def test_other_root_datasets_are_named_as_the_root_not_as_group_empty(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    _add(matches, "info", np.arange(3))
    code, captured, out = _run(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists()
    err = captured.err.strip().splitlines()[-1]
    assert err.startswith(f"error: {matches}: the file's root group ('/') holds 'info' but no "
                          "'matches0'") and err.endswith("or remove those datasets")
