"""pipeline.inputs.hloc: a pair group naming an image whose group in features.h5 holds no
'keypoints' (an extraction cut short, a dataset renamed) is named as such, not as an image
missing from the features file."""

import h5py
import numpy as np

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair

NAMES = ["a.jpg", "db/b.jpg", "c.jpg"]
M = 12


def _write(d):
    feats, matches = d / "features.h5", d / "matches.h5"
    rng = np.random.default_rng(0)
    with h5py.File(feats, "w") as fd:
        for name in NAMES:
            g = fd.create_group(name)
            g.create_dataset("keypoints", data=rng.uniform(0, 100, (M, 2)).astype(np.float32))
            g.create_dataset("descriptors", data=rng.uniform(0, 1, (8, M)).astype(np.float32))
    with h5py.File(matches, "w") as fd:
        for i, j in ((0, 1), (1, 2), (0, 2)):
            m0 = np.full(M, -1, np.int32)
            m0[:8] = np.arange(8)
            fd.create_group(names_to_pair(NAMES[i], NAMES[j])).create_dataset("matches0", data=m0)
    return feats, matches


def _run(capsys, tmp_path, feats, matches):
    out = tmp_path / "out.h5"
    code = main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--out", str(out), "--no-rerun"])
    return code, capsys.readouterr(), out


def test_the_files_as_written_are_read(tmp_path, capsys):
    code, captured, _ = _run(capsys, tmp_path, *_write(tmp_path))
    assert code == 0, captured.err


def test_an_image_group_without_keypoints_is_named_as_such(tmp_path, capsys):
    # it was 'names 'db-b.jpg', not an image of the features file: are features.h5 and
    # matches.h5 of the same images?', though the image's group is in the features file
    feats, matches = _write(tmp_path)
    with h5py.File(feats, "a") as fd:
        del fd["db/b.jpg/keypoints"]
    code, captured, out = _run(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        "error: matches file: pair group 'a.jpg/db-b.jpg' names 'db/b.jpg', whose group in the "
        "features file holds no 'keypoints' dataset (only 'descriptors'): extract the features "
        "of that image again, or remove the pair group")


def test_an_image_missing_from_the_features_file_is_still_named_so(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    with h5py.File(feats, "a") as fd:
        del fd["c.jpg"]
    code, captured, _ = _run(capsys, tmp_path, feats, matches)
    assert code == 2
    assert "names 'c.jpg', not an image of the features file" in captured.err
