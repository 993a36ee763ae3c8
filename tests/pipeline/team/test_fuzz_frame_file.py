"""Fuzzed frame files of an online step's robot (TEAM.json ``data.frames`` of kind
``online-match``): a damaged file, or arrays of other shapes, dtypes or values, give a view as
written or an InputError naming the file; they ended in a KeyError or ValueError traceback
from NumPy, or were taken (a K of shape (2,)) for a later step to trip over."""

import io
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.team.online_match import load_frame, write_frame
from pipeline.types import View

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, read_or_refuse  # noqa: E402

K = np.array([[50.0, 0, 15.5], [0, 50.0, 11.5], [0, 0, 1]])


def _arrays(posed: bool) -> dict:
    rng = np.random.default_rng(0)
    out = {"image": rng.integers(0, 255, (24, 32, 3), dtype=np.uint8), "K": K,
           "intrinsics_known": np.array([True])}
    if posed:
        out.update(R=np.eye(3), t=np.array([0.0, 0.0, 1.0]))
    return out


_VALUES = st.sampled_from([np.zeros(2), np.zeros((3, 3, 1)), np.full((3, 3), np.nan),
                           np.full((3, 3), np.inf), np.array([1]), np.array(["x"]),
                           np.zeros((24, 32), np.float32), np.zeros((1, 1), np.uint8),
                           np.zeros((24, 32, 4), np.uint8), np.zeros((0, 0, 3), np.uint8),
                           np.array([True, False]), np.array([[1, 2], [3, 4]]), np.array(1.5),
                           np.zeros((24, 32), np.uint8), np.eye(3, dtype=np.float32)])


@st.composite
def frames(draw):
    arrays = _arrays(draw(st.booleans()))
    for _ in range(draw(st.integers(1, 2))):
        key = draw(st.sampled_from(sorted(arrays) + ["R", "t"]))
        if draw(st.booleans()) and key in arrays:
            del arrays[key]
        else:
            arrays[key] = draw(_VALUES)
    return arrays


def _check(view) -> None:
    assert view.image.dtype == np.uint8 and view.image.ndim in (2, 3)
    assert view.K.shape == (3, 3) and np.isfinite(view.K).all()
    assert (view.R is None) == (view.t is None)
    if view.R is not None:
        assert view.R.shape == (3, 3) and view.t.shape == (3,)


@FUZZ
@given(frames())
def test_a_frame_of_other_arrays_is_read_or_refused(arrays):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f0.npz"
        np.savez(path, **arrays)
        view = read_or_refuse(lambda: load_frame(path, "frame-0"), str(path))
        if view is not None:
            _check(view)


@FUZZ
@given(st.data())
def test_a_damaged_frame_file_is_read_or_refused(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f0.npz"
        write_frame(path, View("f", *(_arrays(True)[k] for k in ("image", "K")),
                               R=np.eye(3), t=np.zeros(3)))
        path.write_bytes(data.draw(bytes_mutant(path.read_bytes(), max_ops=3)))
        view = read_or_refuse(lambda: load_frame(path, "frame-0"), str(path))
        if view is not None:
            _check(view)


@pytest.mark.parametrize("content, needle", [
    (b"not a frame", "is not a frame of an online step"),
    (None, "has no array 'K'"),
    ("K2", "K [0.0, 0.0] is not a (3, 3) array of finite numbers"),
    ("npy", "one array (.npy)")])
def test_a_frame_file_that_is_not_one_is_named(tmp_path, content, needle):
    path = tmp_path / "f0.npz"
    if content is None:
        np.savez(path, image=np.zeros((4, 4), np.uint8), intrinsics_known=np.array([True]))
    elif content == "K2":
        np.savez(path, image=np.zeros((4, 4), np.uint8), K=np.zeros(2),
                 intrinsics_known=np.array([True]))
    elif content == "npy":
        buf = io.BytesIO()
        np.save(buf, np.zeros(3))
        path.write_bytes(buf.getvalue())
    else:
        path.write_bytes(content)
    with pytest.raises(InputError) as exc:
        load_frame(path, "frame-0")
    assert f"frame file {str(path)!r}" in str(exc.value) and needle in str(exc.value)
