"""clean-h5 given the features file as --matches (both options naming features.h5, or the
two files swapped by hand): named as a features file, not as another tool's layout."""

import numpy as np
from hloc_files import first_matched, run_clean_h5, write_h5

NAMES = ["a.jpg", "b.jpg", "c.jpg"]
M = 10


def _write(d):
    return write_h5(d, NAMES, M, lambda k: first_matched(M, 6, np.int16), descriptors=True)


def test_the_files_in_their_places_are_read(tmp_path, capsys):
    code, captured, _ = run_clean_h5(capsys, tmp_path, *_write(tmp_path))
    assert code == 0, captured.err


def test_the_features_file_as_matches_is_named_a_features_file(tmp_path, capsys):
    # it said "group 'a.jpg' holds 'keypoints', 'descriptors' but no 'matches0' (nor 2 other
    # group(s)): not hloc's layout ...; write the matches so, or remove the group": advice
    # to edit the features file
    feats, _ = _write(tmp_path)
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, feats)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {feats}: its 3 group(s) of 'keypoints' without 'matches0' (e.g. 'a.jpg') are "
        "images, not pairs: a features file, not hloc's matches.h5; give the matches file as "
        "--matches")
