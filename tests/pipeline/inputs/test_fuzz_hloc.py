"""Fuzzed hloc files of ``clean-h5`` (``features.h5``, ``matches.h5``, ``pairs.txt``): a
dataset of another dtype or shape, values out of range (NaN, inf, negative, huge), groups
missing or misplaced, damaged bytes: the reader returns valid links or an InputError naming
the file."""

import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pipeline.inputs.hloc import names_to_pair, read_h5

sys.path.insert(0, str(Path(__file__).parents[1]))
from mutants import FUZZ, bytes_mutant, read_or_refuse, text_mutant  # noqa: E402

NAMES = ["a.jpg", "b.jpg", "c.jpg"]
M = 5
PAIRS = ((0, 1), (1, 2), (0, 2))


def _keypoints(k: int) -> np.ndarray:
    return (np.arange(2 * M, dtype=np.float32).reshape(M, 2) + 3 * k)


def _matches0() -> np.ndarray:
    return np.array([0, 1, -1, 3, 2], dtype=np.int32)


def _damaged(draw, arr: np.ndarray) -> np.ndarray:
    """``arr`` of another dtype, shape or values."""
    op = draw(st.sampled_from(["dtype", "shape", "value", "value", "empty", "scalar"]))
    if arr.size == 0 or arr.ndim == 0:  # already emptied, or one value
        return arr
    if op == "dtype":
        dt = draw(st.sampled_from([np.float16, np.float64, np.int8, np.uint8, np.uint64,
                                   np.int64, np.bool_, np.complex64, "S3", np.float32]))
        try:
            return arr.astype(dt)
        except (ValueError, OverflowError):  # text that is no number of that type
            return arr
    if op == "shape":
        shape = draw(st.sampled_from([(M, 1), (1, M), (M - 1,), (M + 1,), (M, 3), (2, M),
                                      (M, 2, 1), (M * 2,)]))
        flat = np.resize(arr.ravel(), int(np.prod(shape)))
        return flat.reshape(shape)
    if op == "value":
        if arr.dtype.kind not in "fiu":
            return arr
        out = arr.astype(np.float64 if arr.dtype.kind == "f" else np.int64).reshape(-1)
        vals = [-1, -2, M, M + 7, 2**31 - 1, -2**31, 0] + (
            [np.nan, np.inf, -np.inf, -5.0, 1e30, 1e-40] if out.dtype.kind == "f" else [])
        out[draw(st.integers(0, out.size - 1))] = draw(st.sampled_from(vals))
        out = out.reshape(arr.shape)
        return out.astype(arr.dtype) if arr.dtype.kind != "f" else out.astype(
            draw(st.sampled_from([np.float32, np.float64])))
    if op == "empty":
        return arr[:0]
    return np.asarray(arr.flat[0])


@st.composite
def hloc_files(draw):
    """The two files' contents as nested dicts, damaged in one to three places."""
    feats = {n: {"keypoints": _keypoints(k)} for k, n in enumerate(NAMES)}
    if draw(st.booleans()):
        for n in NAMES:
            feats[n]["descriptors"] = np.ones((4, M), np.float32)
            feats[n]["scores"] = np.ones(M, np.float32)
    matches = {names_to_pair(NAMES[i], NAMES[j]): {"matches0": _matches0(),
                                                  "matching_scores0": np.full(M, 0.5, np.float32)}
               for i, j in PAIRS}
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(["feats", "matches"]))
        doc = feats if where == "feats" else matches
        group = draw(st.sampled_from(sorted(doc)))
        op = draw(st.sampled_from(["array", "array", "array", "drop_dataset", "drop_group",
                                   "rename_group", "flip_pair"]))
        if op == "array" and doc[group]:
            key = draw(st.sampled_from(sorted(doc[group])))
            doc[group][key] = _damaged(draw, doc[group][key])
        elif op == "drop_dataset" and doc[group]:
            del doc[group][draw(st.sampled_from(sorted(doc[group])))]
        elif op == "drop_group":
            del doc[group]
        elif op == "rename_group":
            doc[draw(st.sampled_from(["x.jpg", "a.jpg/b", "", "\u00e9.jpg", "a.jpg/b.jpg/c"]))
                .strip("/") or "z"] = doc.pop(group)
        elif op == "flip_pair" and "/" in group:
            a, b = group.split("/", 1)
            doc[f"{b}/{a}"] = doc.pop(group)
    return feats, matches


def _write(path: Path, doc: dict) -> None:
    with h5py.File(path, "w") as fd:
        for group, datasets in doc.items():
            g = fd.require_group(group)
            for key, arr in datasets.items():
                g.create_dataset(key, data=arr)


def _check(out) -> None:
    lk = out.links
    n = len(out.names)
    assert n >= 2 and len(out.keypoints) == n
    for kp in out.keypoints:
        assert kp.ndim == 2 and kp.shape[1] == 2 and np.isfinite(kp).all()
    m = out.features_per_camera
    assert (lk.cam_i < lk.cam_j).all() and (lk.cam_j < n).all()
    assert ((lk.feat_i >= 0) & (lk.feat_i < m[lk.cam_i])).all()
    assert ((lk.feat_j >= 0) & (lk.feat_j < m[lk.cam_j])).all()
    assert np.isfinite(lk.quality).all()


@FUZZ
@given(hloc_files())
def test_damaged_hloc_datasets_are_read_or_refused(files):
    with tempfile.TemporaryDirectory() as d:
        feats, matches = Path(d) / "features.h5", Path(d) / "matches.h5"
        _write(feats, files[0])
        _write(matches, files[1])
        out = read_or_refuse(lambda: read_h5(feats, matches), ".h5")
        if out is not None:
            _check(out)


@FUZZ
@given(st.sampled_from(["features", "matches"]), st.data())
def test_a_damaged_hloc_file_is_read_or_refused(which, data):
    with tempfile.TemporaryDirectory() as d:
        feats, matches = Path(d) / "features.h5", Path(d) / "matches.h5"
        f, m = data.draw(hloc_files()) if data.draw(st.booleans()) else (
            {n: {"keypoints": _keypoints(k)} for k, n in enumerate(NAMES)},
            {names_to_pair(NAMES[i], NAMES[j]): {"matches0": _matches0()} for i, j in PAIRS})
        _write(feats, f)
        _write(matches, m)
        path = feats if which == "features" else matches
        path.write_bytes(data.draw(bytes_mutant(path.read_bytes(), max_ops=4)))
        out = read_or_refuse(lambda: read_h5(feats, matches), ".h5")
        if out is not None:
            _check(out)


PAIRS_TXT = "a.jpg b.jpg\nb.jpg c.jpg\n# a comment\na.jpg c.jpg\n"


@FUZZ
@given(st.one_of(text_mutant(PAIRS_TXT).map(lambda s: s.encode("utf-8", "surrogatepass")),
                 bytes_mutant(PAIRS_TXT.encode())))
def test_a_damaged_pairs_file_is_read_or_refused(content):
    with tempfile.TemporaryDirectory() as d:
        feats, matches, pairs = (Path(d) / n for n in ("features.h5", "matches.h5", "pairs.txt"))
        _write(feats, {n: {"keypoints": _keypoints(k)} for k, n in enumerate(NAMES)})
        _write(matches, {names_to_pair(NAMES[i], NAMES[j]): {"matches0": _matches0()}
                         for i, j in PAIRS})
        pairs.write_bytes(content)
        out = read_or_refuse(lambda: read_h5(feats, matches, pairs), "pairs")
        if out is not None:
            _check(out)
