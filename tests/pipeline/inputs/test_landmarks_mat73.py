"""Labelled-landmark folders whose keypoints are MATLAB v7.3 MAT files (HDF5, ``save
-v7.3``): read as the older MAT versions are, or refused naming what pts_coord holds."""

from pathlib import Path

import h5py
import numpy as np
import pytest
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder

PTS = np.array([[10.0, 12.0], [30.0, 20.0], [50.0, 40.0], [20.0, 35.0]])


def _image(path: Path, size=(64, 48)) -> None:
    rng = np.random.default_rng(len(path.name))
    Image.fromarray(rng.integers(0, 255, size[::-1], dtype=np.uint8)).save(path)


def _mat73(path: Path, name: str, value, matlab_class: str = "double") -> None:
    """A MAT file as MATLAB's ``save -v7.3`` lays it out: a 512-byte MAT header in the HDF5
    user block, each variable a dataset stored column-major (a 2 x K matrix is K x 2 in HDF5)
    with its ``MATLAB_class``."""
    with h5py.File(path, "w", userblock_size=512) as f:
        ds = f.create_dataset(name, data=np.asarray(value).T)
        ds.attrs["MATLAB_class"] = np.bytes_(matlab_class)
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sun Jan  7 10:00:00 2024 HDF5"
    with open(path, "r+b") as f:
        f.write(text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")


def test_v73_mat_keypoints_are_read(tmp_path):
    for k in range(3):
        _image(tmp_path / f"view{k}.png")
        pts = PTS + k
        if k == 1:
            pts = pts.copy()
            pts[2] = np.nan  # a landmark this view does not see
        _mat73(tmp_path / f"view{k}.mat", "pts_coord", pts.T)
    frames = load_landmark_folder(tmp_path, descriptors="sift")
    assert [f.keypoint_file for f in frames] == ["view0.mat", "view1.mat", "view2.mat"]
    np.testing.assert_allclose(frames[0].keypoints, PTS)
    np.testing.assert_allclose(frames[2].keypoints, PTS + 2)
    assert frames[1].landmarks.tolist() == [0, 1, 3]


def test_v73_mat_of_text_names_what_pts_coord_holds(tmp_path):
    for k in range(2):
        _image(tmp_path / f"view{k}.png")
    _mat73(tmp_path / "view0.mat", "pts_coord", PTS.T)
    _mat73(tmp_path / "view1.mat", "pts_coord", np.full((2, 4), ord("a"), np.uint16), "char")
    with pytest.raises(InputError, match=r"view1.mat: pts_coord holds text, expected a numeric "
                                         r"2 x K array"):
        load_landmark_folder(tmp_path, descriptors="sift")


@pytest.mark.parametrize("sizes", [[np.inf, 0.0], [-1.0, 0.0], [1e30, 0.0], [2.0, 3.0], [0.5, 0]])
def test_v73_mat_marked_empty_with_sizes_of_no_empty_matrix_is_refused(tmp_path, sizes):
    # an empty matrix is stored as its sizes with MATLAB_empty: inf, -1 or 1e30 there ended in
    # an OverflowError or ValueError traceback, 0.5 was read as 0, 2 x 3 as an empty matrix
    for k in range(2):
        _image(tmp_path / f"view{k}.png")
    _mat73(tmp_path / "view0.mat", "pts_coord", PTS.T)
    _mat73(tmp_path / "view1.mat", "pts_coord", np.asarray(sizes))
    with h5py.File(tmp_path / "view1.mat", "a") as f:
        f["pts_coord"].attrs["MATLAB_empty"] = np.uint8(1)
    with pytest.raises(InputError, match=r"view1.mat: pts_coord is marked empty \(MATLAB_empty\) "
                                         r"but holds .*, not the sizes of an empty matrix"):
        load_landmark_folder(tmp_path, descriptors="sift")
