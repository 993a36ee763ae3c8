"""Fuzzed files of a labelled-landmark folder (``run-landmarks``: ``NAME.txt`` / ``NAME.mat``
keypoints, ``NAME.scf`` descriptors): a damaged file gives frames of valid keypoints and
descriptors or an InputError naming a file of the folder."""

import io
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from hypothesis import given
from hypothesis import strategies as st
from PIL import Image

from pipeline.errors import InputError
from pipeline.inputs.landmarks import load_landmark_folder

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, read_or_refuse, text_mutant  # noqa: E402

KP = {"a": [[10.0, 10.0], [50.0, 50.0], [80.5, 20.0]],
      "b": [[12.0, 11.0], [52.0, 49.0], [float("nan"), float("nan")]],
      "c": [[9.0, 12.5], [48.0, 51.0], [79.0, 22.0]]}
DESC = {"a": [[-2, 1], [0, 2], [1, 1]], "b": [[1, 2], [1, -1], [0, 0]],
        "c": [[-2, 0], [1, -1], [0.5, 1]]}


def _text(rows) -> str:
    out = io.StringIO()
    np.savetxt(out, np.asarray(rows, dtype=float))
    return out.getvalue()


def _folder(d: Path, mat: bool = False) -> None:
    for name in KP:
        Image.new("L", (100, 100), 128).save(d / f"{name}.png")
        if mat:
            scipy.io.savemat(d / f"{name}.mat", {"pts_coord": np.asarray(KP[name]).T})
        else:
            (d / f"{name}.txt").write_text(_text(KP[name]))
        (d / f"{name}.scf").write_text(_text(DESC[name]))


def _check(frames) -> None:
    assert len(frames) == 3
    for f in frames:
        kp = np.asarray(f.keypoints)
        assert kp.ndim == 2 and kp.shape[1] == 2 and np.isfinite(kp).all()
        assert ((kp >= -0.5) & (kp <= 100.5)).all()


def _load(d: Path):
    frames = read_or_refuse(lambda: load_landmark_folder(d), str(d))
    if frames is not None:
        _check(frames)
    return frames


FILES = st.sampled_from([("a", ".txt"), ("b", ".txt"), ("a", ".scf"), ("c", ".scf")])


@FUZZ
@given(FILES, st.data())
def test_a_damaged_keypoint_or_descriptor_table_is_read_or_refused(which, data):
    name, suffix = which
    valid = _text((KP if suffix == ".txt" else DESC)[name])
    content = data.draw(st.one_of(text_mutant(valid).map(
        lambda s: s.encode("utf-8", "surrogatepass")), bytes_mutant(valid.encode())))
    with tempfile.TemporaryDirectory() as d:
        _folder(Path(d))
        (Path(d) / f"{name}{suffix}").write_bytes(content)
        if _load(Path(d)) is not None:
            # numbers written in digits 0-9 (or nan, inf): Python's float() also reads "1_0"
            # as 10, and other scripts' digits
            body = "".join(ln.split("#")[0] for ln in content.decode("utf-8-sig").splitlines())
            assert re.fullmatch(r"([0-9eE+.,\s-]|nan|inf)*", body, re.I), content


_ARRAYS = st.one_of(
    st.sampled_from([np.zeros((2, 0)), np.zeros((0, 2)), np.zeros((3, 3)), np.ones(3),
                     np.array([["ab", "cd"]]), np.array([[1 + 2j, 3j], [1, 2]]),
                     np.array([[True, False], [True, True]]), np.full((2, 3), np.inf),
                     np.full((2, 3), np.nan), np.array([[1e308, 5], [5, 5]]),
                     np.array([[10, 50], [10, 50]], dtype=np.uint8), np.zeros((2, 3, 1)),
                     np.array([[-1.0, 10.0], [-1.0, 10.0]]), np.array([{"a": 1}], dtype=object),
                     np.array([[10.0, 50, 80], [10, 50, 20]], dtype=np.float32)]),
    st.tuples(st.integers(0, 3), st.integers(0, 4)).flatmap(
        lambda s: st.lists(st.one_of(st.floats(-10, 200), st.sampled_from([np.nan, np.inf, -np.inf])),
                           min_size=s[0] * s[1], max_size=s[0] * s[1]).map(
            lambda v: np.asarray(v, dtype=float).reshape(s))))


@FUZZ
@given(_ARRAYS, st.sampled_from(["pts_coord", "pts", "PTS_COORD"]))
def test_a_mat_file_of_any_array_is_read_or_refused(arr, key):
    with tempfile.TemporaryDirectory() as d:
        _folder(Path(d), mat=True)
        try:
            scipy.io.savemat(Path(d) / "b.mat", {key: arr})
        except (TypeError, ValueError):
            return  # an array scipy cannot write
        _load(Path(d))


@FUZZ
@given(st.data())
def test_a_damaged_mat_file_is_read_or_refused(data):
    with tempfile.TemporaryDirectory() as d:
        _folder(Path(d), mat=True)
        path = Path(d) / "b.mat"
        path.write_bytes(data.draw(bytes_mutant(path.read_bytes(), max_ops=2)))
        _load(Path(d))


@pytest.mark.parametrize("suffix, row", [(".txt", "1_0 10"), (".txt", "\u0661 10"),
                                         (".scf", "1 1_0")])
def test_a_number_not_written_in_digits_is_refused_by_name(tmp_path, suffix, row):
    _folder(tmp_path)
    path = tmp_path / f"a{suffix}"
    path.write_text(row + "\n" + "".join(path.read_text().splitlines(True)[1:]))
    bad = repr(row) if suffix == ".txt" else "'1_0'"  # the row, or the value
    with pytest.raises(InputError, match=re.escape(bad)) as exc:
        load_landmark_folder(tmp_path)
    assert path.name in str(exc.value)


def _mat73(path: Path, value, matlab_class, empty) -> None:
    """A MAT file as MATLAB's ``save -v7.3`` lays it out (HDF5 after a 512-byte header)."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        ds = f.create_dataset("pts_coord", data=np.asarray(value).T)
        if matlab_class is not None:
            ds.attrs["MATLAB_class"] = matlab_class
        if empty is not None:
            ds.attrs["MATLAB_empty"] = empty
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sun Jan  7 10:00:00 2024 HDF5"
    with open(path, "r+b") as f:
        f.write(text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")


@FUZZ
@given(_ARRAYS.filter(lambda a: a.dtype.kind != "O"),
       st.sampled_from([None, np.bytes_("double"), np.bytes_("char"), np.bytes_("cell"),
                        np.bytes_("single"), np.bytes_(b"\xff"), 7, np.bytes_("")]),
       st.sampled_from([None, 1, 0, np.uint8(1), np.array([1, 2])]), st.data())
def test_a_v73_mat_file_of_any_array_is_read_or_refused(arr, cls, empty, data):
    with tempfile.TemporaryDirectory() as d:
        _folder(Path(d), mat=True)
        path = Path(d) / "b.mat"
        try:
            _mat73(path, arr, cls, empty)
        except (TypeError, ValueError):
            return  # an array h5py cannot write
        if data.draw(st.booleans()):
            path.write_bytes(data.draw(bytes_mutant(path.read_bytes(), max_ops=3)))
        _load(Path(d))
