"""pipeline.inputs.hloc: a pair group naming an image whose group in features.h5 holds no
'keypoints' (an extraction cut short, a dataset renamed) is named as such, not as an image
missing from the features file."""

import h5py
from hloc_files import first_matched, run_clean_h5, write_h5

NAMES = ["a.jpg", "db/b.jpg", "c.jpg"]
M = 12


def _write(d):
    return write_h5(d, NAMES, M, lambda k: first_matched(M, 8), descriptors=True)


def test_the_files_as_written_are_read(tmp_path, capsys):
    code, captured, _ = run_clean_h5(capsys, tmp_path, *_write(tmp_path))
    assert code == 0, captured.err


def test_an_image_group_without_keypoints_is_named_as_such(tmp_path, capsys):
    # it was 'names 'db-b.jpg', not an image of the features file: are features.h5 and
    # matches.h5 of the same images?', though the image's group is in the features file
    feats, matches = _write(tmp_path)
    with h5py.File(feats, "a") as fd:
        del fd["db/b.jpg/keypoints"]
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: matches file {str(matches)!r}: pair group 'a.jpg/db-b.jpg' names 'db/b.jpg', whose group in the "
        "features file holds no 'keypoints' dataset (only 'descriptors'): extract the features "
        "of that image again, or remove the pair group")


def test_an_image_missing_from_the_features_file_is_still_named_so(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    with h5py.File(feats, "a") as fd:
        del fd["c.jpg"]
    code, captured, _ = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2
    assert "names 'c.jpg', not an image of the features file" in captured.err
