"""MAT label files whose pts_coord is no coordinate table, or whose bytes are gone: refused
naming the file, the variable and what was expected, where they were read as 0 / 1
coordinates (a logical array), named a cell array (a sparse matrix), or called "no readable
variable pts_coord" (a truncated copy, an HDF5 file without MATLAB's header)."""

from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.sparse
from PIL import Image
from scipy.io import savemat

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder

PTS = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0], [20.0, 35.0]])


def _folder(folder: Path, stems=("view0", "view1", "view2"), labels=None) -> Path:
    folder.mkdir(exist_ok=True)
    labels = labels or stems
    for k, (stem, label) in enumerate(zip(stems, labels, strict=True)):
        rng = np.random.default_rng(k)
        Image.fromarray(rng.integers(0, 255, (48, 64), dtype=np.uint8)).save(
            folder / f"{stem}.png")
        savemat(folder / f"{label}.mat", {"pts_coord": (PTS + k).T})
    return folder


@pytest.mark.parametrize("value, what", [
    ((PTS.T > 20), "logical values"),
    (scipy.sparse.csc_matrix(PTS.T), r"a sparse matrix \(save full\(pts_coord\) instead\)")])
def test_logical_and_sparse_pts_coord_are_refused_by_their_class(tmp_path, value, what):
    # a logical array reached the matching as coordinates 0 and 1; a sparse one was called
    # a cell array
    _folder(tmp_path)
    savemat(tmp_path / "view1.mat", {"pts_coord": value})
    with pytest.raises(InputError, match=rf"view1.mat: pts_coord holds {what}, expected a "
                                         r"numeric 2 x K array"):
        load_landmark_folder(tmp_path, descriptors="sift")


def test_a_truncated_mat_file_is_named_damaged_by_name_and_by_order(tmp_path):
    by_name = _folder(tmp_path / "name")
    data = (by_name / "view1.mat").read_bytes()
    (by_name / "view1.mat").write_bytes(data[:-16])
    with pytest.raises(InputError, match=r"view1.mat: pts_coord \(2 x 4 double\) cannot be read "
                                         r"\(.*\): a truncated or damaged MAT file"):
        load_landmark_folder(by_name, descriptors="sift")
    # files paired by name order: the same file was left out and the images miscounted
    by_order = _folder(tmp_path / "order", labels=("lab1", "lab2", "lab3"))
    (by_order / "lab2.mat").write_bytes(data[:-16])
    with pytest.raises(InputError, match=r"lab2.mat: pts_coord \(2 x 4 double\) cannot be read"):
        load_landmark_folder(by_order, descriptors="sift")


def test_a_mat_file_that_is_no_keypoint_file_says_why(tmp_path):
    folder = _folder(tmp_path / "a")
    (folder / "view1.mat").write_bytes(b"")
    with pytest.raises(InputError, match=r"view1.mat: not a keypoint table \(not a MAT file "
                                         r"SciPy can read: .*truncated"):
        load_landmark_folder(folder, descriptors="sift")
    folder = _folder(tmp_path / "b", labels=("lab1", "lab2", "lab3"))
    savemat(folder / "lab2.mat", {"xy": PTS.T})
    with pytest.raises(InputError, match=r"3 images but 2 keypoint files .*; lab2.mat was left "
                                         r"out \(no variable pts_coord; it holds xy\)"):
        load_landmark_folder(folder, descriptors="sift")


def test_v73_files_truncated_or_without_the_mat_header_are_named(tmp_path):
    folder = _folder(tmp_path / "a")
    with h5py.File(folder / "view1.mat", "w") as f:  # h5py's own file: no MAT header
        f.create_dataset("pts_coord", data=PTS.T)
    with pytest.raises(InputError, match=r"view1.mat: an HDF5 file holding pts_coord, but "
                                         r"without the MAT header"):
        load_landmark_folder(folder, descriptors="sift")
    folder = _folder(tmp_path / "b")
    with h5py.File(folder / "view1.mat", "w", userblock_size=512) as f:
        ds = f.create_dataset("pts_coord", data=PTS)
        ds.attrs["MATLAB_class"] = np.bytes_("double")
    with open(folder / "view1.mat", "r+b") as f:
        f.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64 HDF5".ljust(116, b" ")
                + b"\x00" * 8 + b"\x00\x02IM")
    data = (folder / "view1.mat").read_bytes()
    (folder / "view1.mat").write_bytes(data[:-16])
    with pytest.raises(InputError, match=r"view1.mat: not a keypoint table \(a MAT v7.3 \(HDF5\) "
                                         r"file that cannot be opened: .*truncated"):
        load_landmark_folder(folder, descriptors="sift")


def test_a_pts_coord_of_one_row_per_landmark_says_to_transpose_it(tmp_path):
    # K x 2, as a text label file and the hotel's groundT.mat hold the labels: the message
    # gave the shape alone
    _folder(tmp_path)
    savemat(tmp_path / "view1.mat", {"pts_coord": PTS})
    with pytest.raises(InputError, match=r"view1.mat: pts_coord has shape \(4, 2\), expected "
                                         r"2 x K \(row 0 = x, row 1 = y\) \(it holds 4 rows "
                                         r"'x y': save its transpose, pts_coord'\)"):
        load_landmark_folder(tmp_path, descriptors="sift")
