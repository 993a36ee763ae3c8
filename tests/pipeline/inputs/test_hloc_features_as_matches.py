"""clean-h5 given the features file as --matches (both options naming features.h5, or the
two files swapped by hand): named as a features file, not as another tool's layout."""

import h5py
import numpy as np

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair

NAMES = ["a.jpg", "b.jpg", "c.jpg"]
M = 10


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
            m0 = np.full(M, -1, np.int16)
            m0[:6] = np.arange(6)
            fd.create_group(names_to_pair(NAMES[i], NAMES[j])).create_dataset("matches0", data=m0)
    return feats, matches


def _run(capsys, tmp_path, feats, matches):
    out = tmp_path / "out.h5"
    code = main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--out", str(out), "--no-rerun"])
    return code, capsys.readouterr(), out


def test_the_files_in_their_places_are_read(tmp_path, capsys):
    code, captured, _ = _run(capsys, tmp_path, *_write(tmp_path))
    assert code == 0, captured.err


def test_the_features_file_as_matches_is_named_a_features_file(tmp_path, capsys):
    # it said "group 'a.jpg' holds 'keypoints', 'descriptors' but no 'matches0' (nor 2 other
    # group(s)): not hloc's layout ...; write the matches so, or remove the group": advice
    # to edit the features file
    feats, _ = _write(tmp_path)
    code, captured, out = _run(capsys, tmp_path, feats, feats)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {feats}: its 3 group(s) of 'keypoints' without 'matches0' (e.g. 'a.jpg') are "
        "images, not pairs: a features file, not hloc's matches.h5; give the matches file as "
        "--matches")
