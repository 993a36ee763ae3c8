"""clean-h5, as a hostile user would run it: one line on stderr naming the bad value, exit 2,
no traceback, the input files untouched and nothing written."""

import os
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error, refused, run_capped, tree  # noqa: E402
from test_clean_h5 import M, _write  # noqa: E402

P01 = names_to_pair("a.jpg", "sub/b.jpg")


@pytest.fixture
def files(tmp_path):
    d = tmp_path / "in"
    d.mkdir()
    feats, matches = _write(d)
    return d, feats, matches


def _argv(feats, matches, out, *extra):
    return ["clean-h5", "--features", str(feats), "--matches", str(matches), "--out", str(out),
            "--no-rerun", *map(str, extra)]


def _replace(fd, key, data):
    del fd[key]
    fd.create_dataset(key, data=data)



# --- the features file ---------------------------------------------------------------------

UNREADABLE = [("missing", "no such file"), ("folder", "is a folder"),
              ("empty", "is not an HDF5 file"), ("binary", "is not an HDF5 file"),
              ("truncated", "is not an HDF5 file")]


def _spoil(path: Path, case: str, seed: int, keep: int) -> None:
    """Make ``path`` unreadable as ``case`` says (random bytes from ``seed``, or its first
    ``keep`` bytes)."""
    if case in ("missing", "folder"):
        path.unlink()
        if case == "folder":
            path.mkdir()
    elif case == "empty":
        path.write_bytes(b"")
    elif case == "binary":
        path.write_bytes(np.random.default_rng(seed).bytes(keep + 1000))
    else:
        path.write_bytes(path.read_bytes()[:keep])


@pytest.mark.parametrize("case, needle", UNREADABLE)
@pytest.mark.parametrize("which, seed, keep", [("features", 0, 3000), ("matches", 1, 2500)])
def test_unreadable_input_file(files, tmp_path, capsys, which, seed, keep, case, needle):
    d, feats, matches = files
    _spoil(feats if which == "features" else matches, case, seed, keep)
    refused(capsys, _argv(feats, matches, tmp_path / "o.h5"), d, needle, f"{which} file")
    assert not (tmp_path / "o.h5").exists()


def test_a_device_as_features_file(files, tmp_path, capsys):
    d, _, matches = files
    refused(capsys, _argv("/dev/null", matches, tmp_path / "o.h5"), d, "not a regular file")


@pytest.mark.parametrize("edit, needle", [
    (lambda fd: [fd[n].__delitem__("keypoints") for n in ("a.jpg", "sub/b.jpg", "c.jpg")],
     "no image group with a 'keypoints' dataset"),
    (lambda fd: _replace(fd, "a.jpg/keypoints", np.zeros((M, 3), np.float32)), "shape (20, 3)"),
    (lambda fd: _replace(fd, "a.jpg/keypoints", np.zeros(M, np.float32)), "shape (20,)"),
    (lambda fd: _replace(fd, "a.jpg/keypoints", 5.0), "shape ()"),
    (lambda fd: _replace(fd, "a.jpg/keypoints", np.array([[b"x", b"y"]] * M)), "dtype |S1"),
    (lambda fd: fd["a.jpg/keypoints"].__setitem__(3, [np.nan, 1]), "keypoint 3 is [nan, 1.0]"),
    (lambda fd: fd["a.jpg/keypoints"].__setitem__(0, [np.inf, 1]), "keypoint 0 is [inf, 1.0]"),
    (lambda fd: [fd.__delitem__(n) for n in ("c.jpg", "sub")], "1 image(s)"),
    # complex keypoints were read, their imaginary part dropped without a word
    (lambda fd: _replace(fd, "a.jpg/keypoints", np.ones((M, 2), np.complex64) * (1 + 5j)),
     "have dtype complex64; expected real numbers"),
], ids=["no-keypoints", "3-columns", "1-d", "scalar", "strings", "nan", "inf", "one-image",
        "complex"])
def test_malformed_keypoints(files, tmp_path, capsys, edit, needle):
    d, feats, matches = files
    with h5py.File(feats, "a") as fd:
        edit(fd)
    refused(capsys, _argv(feats, matches, tmp_path / "o.h5"), d, needle, str(feats))


def test_integer_keypoints_are_read(files, tmp_path, capsys):
    """Keypoints stored as integers (pixel centres) are numbers: they were refused with
    'have dtype int32; expected numbers'."""
    d, feats, matches = files
    with h5py.File(feats, "a") as fd:
        for name in ("a.jpg", "sub/b.jpg", "c.jpg"):
            kp = fd[name + "/keypoints"][()]
            _replace(fd, name + "/keypoints", np.rint(kp).astype(np.int32))
    assert main(_argv(feats, matches, tmp_path / "o.h5")) == 0
    assert (tmp_path / "o.h5").is_file()


def test_keypoints_declared_but_not_stored_fail_before_any_allocation(files, tmp_path):
    """A few-kB file declaring 8 GB of keypoints (unwritten chunks): refused, under the cap."""
    d, feats, matches = files
    with h5py.File(feats, "a") as fd:
        del fd["a.jpg/keypoints"]
        fd["a.jpg"].create_dataset("keypoints", shape=(2**30, 2), dtype=np.float32,
                                   chunks=(1024, 2))
    assert feats.stat().st_size < 100_000
    p = run_capped(_argv(feats, matches, tmp_path / "o.h5"))
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert "declare 8589934912 bytes in all but the file stores 320 bytes" in p.stderr


def test_many_datasets_each_under_the_check_are_counted_in_all(files, tmp_path):
    """80 unwritten datasets of 63 MB each (each under the per-dataset check): 5 GB in all."""
    d, feats, matches = files
    rows = 63 * 2**20 // 8
    with h5py.File(feats, "a") as fd:
        for k in range(80):
            fd.create_group(f"extra{k}.jpg").create_dataset(
                "keypoints", shape=(rows, 2), dtype=np.float32, chunks=(4096, 2))
    assert feats.stat().st_size < 2_000_000
    p = run_capped(_argv(feats, matches, tmp_path / "o.h5"))
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert "its 83 keypoints datasets declare" in p.stderr, p.stderr
    assert sorted(x.name for x in tmp_path.iterdir()) == ["in"]


def test_links_chaining_thousands_of_features_run_in_memory_that_follows_the_links(tmp_path):
    """3 images of 3,000 keypoints whose matches chain all 9,000 into one association set:
    the paper's detection would need ~2.9 GB (a ~110 kB input); clean-h5's rule (sync, links
    only: no detection) holds the 9,000 links and makes them consistent under the cap."""
    n = 3000
    feats, matches = tmp_path / "features.h5", tmp_path / "matches.h5"
    rng = np.random.default_rng(0)
    with h5py.File(feats, "w") as fd:
        for name in ("a.jpg", "b.jpg", "c.jpg"):
            fd.create_group(name).create_dataset(
                "keypoints", data=rng.uniform(0, 300, (n, 2)).astype(np.float32))
    with h5py.File(matches, "w") as fd:
        ident = np.arange(n, dtype=np.int32)
        for a, b, m0 in (("a.jpg", "b.jpg", ident), ("b.jpg", "c.jpg", ident),
                         ("a.jpg", "c.jpg", np.roll(ident, 1))):
            fd.create_group(names_to_pair(a, b)).create_dataset("matches0", data=m0)
    p = run_capped(_argv(feats, matches, tmp_path / "o.h5"))
    assert p.returncode == 0, p.stderr
    assert "conflictive sets: 1 before, 0 after" in p.stdout, p.stdout
    assert (tmp_path / "o.h5").exists()


def test_the_memory_limit_of_clean_h5_is_checked(files, tmp_path, capsys):
    d, feats, matches = files
    refused(capsys, _argv(feats, matches, tmp_path / "o.h5", "--max-memory-gb", "nan"), d,
            "--max-memory-gb 'nan'")
    refused(capsys, _argv(feats, matches, tmp_path / "o.h5", "--max-memory-gb", "0.000001"), d,
            "keypoints of the features file", "--max-memory-gb")


def test_keypoints_far_outside_any_image_draw_a_bounded_canvas():
    from pipeline.runs.clean_h5 import MAX_CANVAS_SIDE, _size_of

    assert _size_of(np.array([[1e30, 1e30]], np.float32)) == (MAX_CANVAS_SIDE, MAX_CANVAS_SIDE)
    assert _size_of(np.array([[-5.0, 3.0]], np.float32)) == (16, 16)


@pytest.mark.parametrize("which", ["features", "matches"])
def test_a_file_another_program_writes_is_named_as_such(files, tmp_path, capsys, which):
    """HDF5 locks a file another program opened for writing (hloc still at work, a notebook
    that opened it in mode 'a'); it was called 'not an HDF5 file'."""
    import subprocess

    d, feats, matches = files
    held = feats if which == "features" else matches
    writer = subprocess.Popen(
        [sys.executable, "-c", "import sys, h5py; f = h5py.File(sys.argv[1], 'a'); "
         "print('open', flush=True); sys.stdin.read()", str(held)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        env={k: v for k, v in os.environ.items() if k != "HDF5_USE_FILE_LOCKING"})
    try:
        assert writer.stdout.readline().strip() == "open"
        refused(capsys, _argv(feats, matches, tmp_path / "o.h5"), d,
                "is open for writing in another program", f"{which} file")
    finally:
        writer.communicate("")
    assert not (tmp_path / "o.h5").exists()


# --- the matches file ----------------------------------------------------------------------

@pytest.mark.parametrize("edit, needle", [
    (lambda fd: _replace(fd, P01 + "/matches0", np.full(3, -1, np.int16)), "has shape (3,)"),
    (lambda fd: _replace(fd, P01 + "/matches0", np.full((M, 2), -1, np.int16)),
     "has shape (20, 2)"),
    (lambda fd: _replace(fd, P01 + "/matches0", np.full((1, M), -1, np.int16)),
     "has shape (1, 20) but a.jpg has 20 keypoints; expected (20,)"),
    (lambda fd: _replace(fd, P01 + "/matches0", np.full((M, 1), -1, np.int16)),
     "has shape (20, 1)"),
    (lambda fd: _replace(fd, P01 + "/matching_scores0", np.ones((M, 1), np.float16)),
     "matching_scores0 of pair 'a.jpg/sub-b.jpg' has shape (20, 1)"),
    (lambda fd: _replace(fd, P01 + "/matches0", np.full(M, np.nan)), "dtype float64"),
    (lambda fd: _replace(fd, P01 + "/matches0", np.full(M, 0.5)), "expected integers"),
    (lambda fd: _replace(fd, P01 + "/matches0", np.array([b"ab"] * M)), "dtype |S2"),
    (lambda fd: fd[P01 + "/matches0"].__setitem__(3, 5000), "matches keypoint 5000"),
    (lambda fd: fd[P01 + "/matches0"].__setitem__(3, -5), "holds -5"),
    (lambda fd: _replace(fd, P01 + "/matches0", np.full(M, 2**62, np.int64)),
     "matches keypoint 4611686018427387904"),
    # 2**64 - 1 would read -1 (no match) once cast to int64
    (lambda fd: _replace(fd, P01 + "/matches0", np.full(M, 2**64 - 1, np.uint64)),
     "matches keypoint 18446744073709551615"),
    # hloc's -1 (no match) written unsigned: the message said only 'matches keypoint 65535'
    (lambda fd: _replace(fd, P01 + "/matches0", np.full(M, -1, np.int16).astype(np.uint16)),
     "(uint16 is unsigned: hloc's -1, no match, reads as 65535; store matches0 as a signed "
     "integer, e.g. int32)"),
    (lambda fd: _replace(fd, P01 + "/matching_scores0", np.ones(3, np.float16)),
     "matching_scores0 of pair 'a.jpg/sub-b.jpg' has shape (3,)"),
    (lambda fd: _replace(fd, P01 + "/matching_scores0", np.full(M, np.nan, np.float32)),
     "holds nan"),
    (lambda fd: _replace(fd, P01 + "/matching_scores0", np.array([b"ab"] * M)),
     "matching_scores0 of pair 'a.jpg/sub-b.jpg' have dtype |S2"),
    (lambda fd: fd.create_group("zz.jpg/yy.jpg").create_dataset("matches0",
                                                                data=np.full(M, -1)),
     "'zz.jpg/yy.jpg' names 'zz.jpg', 'yy.jpg', not an image of the features file: are "
     "features.h5 and matches.h5 of the same images?"),
    (lambda fd: fd.create_group("a.jpg/yy.jpg").create_dataset("matches0",
                                                               data=np.full(M, -1)),
     "'a.jpg/yy.jpg' names 'yy.jpg', not an image of the features file"),
    (lambda fd: fd.create_group("a.jpg/a.jpg").create_dataset("matches0", data=np.arange(M)),
     "pairs image 'a.jpg' with itself"),
    # one image pair stored twice: reading both made the cleaned copy of one lose every match
    (lambda fd: fd.copy(P01, "sub-b.jpg/a.jpg"),
     "pair groups 'a.jpg/sub-b.jpg' and 'sub-b.jpg/a.jpg' both hold the image pair"),
    (lambda fd: fd.copy(P01, "a.jpg_sub-b.jpg"),
     "pair groups 'a.jpg/sub-b.jpg' and 'a.jpg_sub-b.jpg' both hold the image pair"),
    # another tool's layout, (K, 2) index pairs: that pair was left out and copied uncleaned
    (lambda fd: fd[P01].move("matches0", "matches"),
     "group 'a.jpg/sub-b.jpg' holds 'matches', 'matching_scores0' but no 'matches0'"),
], ids=["short", "2-d", "row", "column", "scores-column", "float-nan", "float-fraction", "strings", "out-of-range",
        "below-minus-one", "int64-huge", "uint64-max", "uint16-minus-one", "scores-short", "scores-nan",
        "scores-strings", "unknown-pair", "half-unknown-pair", "self-pair", "pair-both-orders",
        "pair-old-and-new-key", "matches-not-matches0"])
def test_malformed_matches(files, tmp_path, capsys, edit, needle):
    d, feats, matches = files
    with h5py.File(matches, "a") as fd:
        edit(fd)
    refused(capsys, _argv(feats, matches, tmp_path / "o.h5"), d, needle)
    assert not (tmp_path / "o.h5").exists()


# --- the pairs file ------------------------------------------------------------------------

@pytest.mark.parametrize("content, needle", [
    (b"", "holds no pair"),
    (b"\x90\x00\xff binary", "is not a UTF-8 text file"),
    ("a.jpg \xe9.jpg\n".encode("latin-1"), "is not a UTF-8 text file"),
    (b"a.jpg sub/b.jpg c.jpg\n", "must hold two image names"),
    (b"a.jpg a.jpg\n", "pairs an image with itself"),
    (b"a.jpg x.jpg\n", "image 'x.jpg' has no keypoints"),
    (b"a.jpg sub/b.jpg\n" + b"a" * 200_000 + b" sub/b.jpg\n", "line 2: longer than 65536"),
    ("a.jpg sub/b.jpg\u2028a.jpg c.jpg\n".encode(), "must hold two image names"),
], ids=["empty", "binary", "latin-1", "three-names", "self", "unknown-image", "long-line",
        "u2028"])
def test_malformed_pairs_file(files, tmp_path, capsys, content, needle):
    d, feats, matches = files
    (d / "pairs.txt").write_bytes(content)
    refused(capsys, _argv(feats, matches, tmp_path / "o.h5", "--pairs", d / "pairs.txt"), d,
            needle)


@pytest.mark.parametrize("case, needle", [("missing", "no such file"), ("folder", "is a folder")])
def test_pairs_not_a_file(files, tmp_path, capsys, case, needle):
    d, feats, matches = files
    pairs = d / "nope.txt" if case == "missing" else d
    refused(capsys, _argv(feats, matches, tmp_path / "o.h5", "--pairs", pairs), d, needle,
            "--pairs")


# --- outputs -------------------------------------------------------------------------------

@pytest.mark.parametrize("case, needle", [
    ("features", "is the input file given as --features"),
    ("matches", "is the input file given as --matches"),
    ("folder", "is a folder"),
    ("devnull", "is not a regular file"),
    ("dangling-symlink", "is a symbolic link"),
    ("symlink-to-matches", "is a symbolic link"),
    ("empty", "--out ''"),
], ids=str)
def test_out_that_names_an_input_or_a_special_entry(files, tmp_path, capsys, case, needle):
    d, feats, matches = files
    out = {"features": feats, "matches": matches, "folder": tmp_path / "od",
           "devnull": "/dev/null", "dangling-symlink": tmp_path / "ln.h5",
           "symlink-to-matches": tmp_path / "ln.h5", "empty": ""}[case]
    if case == "folder":
        (tmp_path / "od").mkdir()
    elif case == "dangling-symlink":
        os.symlink(tmp_path / "target.h5", out)
    elif case == "symlink-to-matches":
        os.symlink(matches, out)
    before = tree(tmp_path)
    assert main(_argv(feats, matches, out, "--overwrite")) == 2
    one_line_error(capsys, needle)
    assert tree(tmp_path) == before
    assert not (tmp_path / "target.h5").exists()


def test_existing_out_needs_overwrite(files, tmp_path, capsys):
    d, feats, matches = files
    (tmp_path / "o.h5").write_bytes(b"precious")
    assert main(_argv(feats, matches, tmp_path / "o.h5")) == 2
    one_line_error(capsys, "already exists; pass --overwrite")
    assert (tmp_path / "o.h5").read_bytes() == b"precious"


@pytest.mark.parametrize("case, needle", [
    ("features", "--report"), ("devnull", "is not a regular file"),
    ("out", "--out and --report name the same file"),
])
def test_report_onto_an_input_or_another_output(files, tmp_path, capsys, case, needle):
    d, feats, matches = files
    report = {"features": feats, "devnull": "/dev/null", "out": tmp_path / "o.h5"}[case]
    before = tree(d)
    assert main(_argv(feats, matches, tmp_path / "o.h5", "--report", report,
                      "--overwrite")) == 2
    one_line_error(capsys, needle)
    assert tree(d) == before and not (tmp_path / "o.h5").exists()


def test_side_file_onto_the_matches_file_is_refused(files, tmp_path, capsys):
    """OUT.links.csv beside --out may not land on an input either."""
    d, feats, matches = files
    links = d / "o.links.csv"
    links.write_text("precious")
    assert main(_argv(feats, matches, d / "o.h5")) == 2
    one_line_error(capsys, "OUT.links.csv", "already exists")
    assert links.read_text() == "precious"


@pytest.mark.parametrize("case", ["missing", "file"])
def test_image_dir_that_is_not_a_folder(files, tmp_path, capsys, case):
    d, feats, matches = files
    image_dir = d / "nope" if case == "missing" else feats
    argv = ["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
            str(tmp_path / "o.h5"), "--image-dir", str(image_dir)]
    refused(capsys, argv, d, "--image-dir", "is not a folder")
    assert not (tmp_path / "o.h5").exists()


def test_ctrl_c_is_one_line_exit_130_and_nothing_written(files, tmp_path, capsys, monkeypatch):
    import pipeline.stages as run

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "consistency_stage", interrupted)
    d, feats, matches = files
    before = tree(d)
    assert main(_argv(feats, matches, tmp_path / "o.h5")) == 130
    err = capsys.readouterr().err
    assert err.startswith("interrupted: clean-h5") and err.count("\n") == 1
    assert tree(d) == before and sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_an_image_dir_lacking_an_image_is_refused_before_anything_is_written(files, tmp_path,
                                                                            capsys):
    d, feats, matches = files
    images = tmp_path / "images"
    images.mkdir()
    (images / "a.jpg").write_bytes(b"")
    (images / "c.jpg").write_bytes(b"")
    argv = ["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
            str(tmp_path / "o.h5"), "--image-dir", str(images)]
    refused(capsys, argv, tmp_path, "--image-dir", "no image 'sub/b.jpg'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["images", "in"]


def test_outputs_follow_the_umask(files, tmp_path, capsys):
    d, feats, matches = files
    mask = os.umask(0o022)
    try:
        assert main(["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
                     str(tmp_path / "o.h5"), "--report", str(tmp_path / "r.json")]) == 0
    finally:
        os.umask(mask)
    for name in ("o.h5", "o.links.csv", "o.rrd", "r.json"):
        assert oct((tmp_path / name).stat().st_mode & 0o777) == oct(0o644), name
