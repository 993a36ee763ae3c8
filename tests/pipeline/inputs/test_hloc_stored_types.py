"""pipeline.inputs.hloc: dataset types hloc never writes, which the reader would take in and
the cleaned copy could not hold, are refused before any work, naming the dataset."""

import h5py
import numpy as np
from hloc_files import run_clean_h5, write_h5

from pipeline.inputs.hloc import names_to_pair

NAMES = ["a.jpg", "b.jpg", "c.jpg"]
M = 12


def _write(d, m0_dtype=np.int32):
    """Three images whose every keypoint is matched: a-b and b-c on the identity, a-c shifted
    by one, so the chains close on other keypoints and the rule must cut."""
    chains = (np.arange(M), np.arange(M), np.roll(np.arange(M), 1))
    return write_h5(d, NAMES, M, lambda k: chains[k].astype(m0_dtype))


def test_signed_matches_that_need_cuts_are_cleaned(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 0 and out.exists(), captured.err
    with h5py.File(out) as fd:
        assert (fd[names_to_pair("a.jpg", "c.jpg")]["matches0"][()] == -1).any() or \
            (fd[names_to_pair("a.jpg", "b.jpg")]["matches0"][()] == -1).any()


def test_unsigned_matches0_without_a_wrapped_minus_one_is_refused(tmp_path, capsys):
    # every keypoint matched, so no entry reads as a wrapped -1; the cleaned copy then had to
    # write -1 into a uint16 dataset: OverflowError, a traceback, exit 1
    feats, matches = _write(tmp_path, np.uint16)
    before = matches.read_bytes()
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {matches}: matches0 of pair 'a.jpg/b.jpg' is stored as uint16, which cannot "
        "hold hloc's -1 (no match) that a cut match is written as; store matches0 as a signed "
        "integer, e.g. int32")
    assert matches.read_bytes() == before


def test_float64_keypoints_past_float32_are_refused_not_read_as_inf(tmp_path, capsys):
    # the finite check ran on the float64 values and the cast to float32 then made them inf
    # (a NumPy RuntimeWarning, and the run went on with infinite keypoints)
    feats, matches = _write(tmp_path)
    with h5py.File(feats, "a") as fd:
        kp = fd["b.jpg/keypoints"][()].astype(np.float64)
        kp[3] = [1e40, 5.0]
        del fd["b.jpg/keypoints"]
        fd["b.jpg"].create_dataset("keypoints", data=kp)
    code, captured, out = run_clean_h5(capsys, tmp_path, feats, matches)
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert "RuntimeWarning" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {feats}: keypoints of 'b.jpg': keypoint 3 is [1e+40, 5.0], beyond the range "
        "of pixel coordinates (float32, as hloc stores them); the file is damaged or not "
        "written by hloc")
