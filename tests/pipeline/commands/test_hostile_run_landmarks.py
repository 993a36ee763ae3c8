"""run-landmarks, as a hostile user would run it: one line on stderr naming the bad value,
exit 2, no traceback, the labelled folder untouched and no run folder written."""

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error, refused, tree  # noqa: E402

K = 8
W, H = 64, 48


@pytest.fixture
def folder(tmp_path):
    """Four 64x48 images, each with K labelled landmarks (NAME.txt) and descriptors (NAME.scf)."""
    d = tmp_path / "labelled"
    d.mkdir()
    rng = np.random.default_rng(0)
    pts = rng.uniform(5, [W - 5, H - 5], (K, 2))
    for k in range(4):
        Image.fromarray(rng.integers(0, 255, (H, W), dtype=np.uint8)).save(d / f"v{k}.png")
        np.savetxt(d / f"v{k}.txt", pts + rng.normal(0, 0.5, pts.shape))
        np.savetxt(d / f"v{k}.scf", rng.random((K, 6)) + np.eye(K, 6))
    return d


def _argv(folder, *extra, out=None):
    return ["run-landmarks", str(folder), "--no-baselines", "--out",
            str(out if out is not None else folder.parent / "run"), *map(str, extra)]


def _fails(capsys, argv, folder, *needles):
    """:func:`refused` on the folder that holds the data set's ``folder``."""
    return refused(capsys, argv, folder.parent, *needles)


def test_the_fixture_runs(folder, capsys):
    assert main(_argv(folder)) == 0
    assert (folder.parent / "run" / "links.csv").is_file()


# --- flags ---------------------------------------------------------------------------------

@pytest.mark.parametrize("flag, value, needle", [
    ("--frames", "-1", "--frames -1: expected 2..4"),
    ("--frames", "1", "--frames 1: expected 2..4"),
    ("--frames", "99", "--frames 99: expected 2..4"),
    ("--epipolar-px", "-1", "--epipolar-px -1.0"),
    ("--epipolar-px", "0", "--epipolar-px 0.0"),
    ("--epipolar-px", "nan", "--epipolar-px nan"),
    ("--epipolar-px", "inf", "--epipolar-px inf"),
    ("--vote-iterations", "0", "--vote-iterations 0"),
    ("--vote-iterations", "-5", "--vote-iterations -5"),
    ("--graph", "nope", "graph 'nope'"),
    ("--graph", "seq:0", "graph 'seq:0'"),
    ("--graph", "seq:nan", "graph 'seq:nan'"),
])
def test_meaningless_flag_values(folder, capsys, flag, value, needle):
    _fails(capsys, _argv(folder, flag, value), folder, needle)


@pytest.mark.parametrize("flag, value", [
    ("--frames", "nan"), ("--frames", "1e9"), ("--vote-iterations", "x"), ("--ratio", "nan"),
    ("--ratio", "inf"), ("--ratio", "-1"), ("--ratio", "0"), ("--descriptors", "foo"),
    ("--geometry", "foo"),
])
def test_wrong_types_are_usage_errors(folder, capsys, flag, value):
    """argparse's own check: exit 2 with 'error: argument FLAG' and no traceback."""
    with pytest.raises(SystemExit) as e:
        main(_argv(folder, flag, value))
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"error: argument {flag}" in err and "Traceback" not in err


@pytest.mark.parametrize("content, needle", [
    ("0,1\n1,2\n2,99\n", "camera index 99 out of range 0..3"),
    ("0,1\n2,2147483646\n", "camera index 2147483646 out of range"),
    ("0,-1\n", "cam_j -1 is negative"),
    (b"\xa0\xff\x00", "is not a UTF-8 text file"),
], ids=["id-outside", "huge-id", "negative", "binary"])
def test_bad_graph_file(folder, tmp_path, capsys, content, needle):
    g = tmp_path / "g.csv"
    g.write_bytes(content if isinstance(content, bytes) else content.encode())
    _fails(capsys, _argv(folder, "--graph", g), folder, needle)


def test_graph_naming_a_folder(folder, tmp_path, capsys):
    _fails(capsys, _argv(folder, "--graph", tmp_path), folder, "is a folder")


# --- the labelled folder -------------------------------------------------------------------

def test_folder_missing_a_file_or_too_small(tmp_path, capsys, folder):
    _fails(capsys, _argv(tmp_path / "nope"), folder, "no such folder")
    _fails(capsys, _argv(folder / "v0.txt"), folder, "a file, not a folder")
    (tmp_path / "empty").mkdir()
    _fails(capsys, _argv(tmp_path / "empty"), folder, "found 0 image(s)")
    for k in (1, 2, 3):
        for suffix in (".png", ".txt", ".scf"):
            (folder / f"v{k}{suffix}").unlink()
    _fails(capsys, _argv(folder), folder, "found 1 image(s)")


@pytest.mark.parametrize("name, content, needle", [
    # a whole 'nan nan' row is a landmark the image does not see; half of one is an error
    ("v1.txt", "nan 3\n" + "1 2\n" * (K - 1), "landmark row 1 is [nan, 3.0]"),
    ("v1.txt", "nan nan\n" * K, "v1.txt: every landmark row is 'nan nan'"),
    ("v1.txt", "inf 3\n" + "1 2\n" * (K - 1), "landmark row 1 is [inf, 3.0]"),
    ("v1.txt", "1 2\n" * (K - 1) + "1e300 3\n", "landmark row 8 at [1e+300, 3.0] lies outside "
                                                "the 64x48 image v1.png"),
    ("v1.txt", "-500 -500\n" + "1 2\n" * (K - 1), "lies outside the 64x48 image"),
    ("v1.txt", "1 2 3\n" + "1 2\n" * (K - 1), "v1.txt: not a keypoint table"),
    ("v1.txt", "x y\n" + "1 2\n" * (K - 1), "v1.txt: not a keypoint table"),
    ("v1.txt", b"\x00\xff\xfe" * 50, "v1.txt: not a keypoint table"),
    # a UTF-16 label file was said to hold 'no row of two numbers'
    ("v1.txt", ("1 2\n" * K).encode("utf-16"), "is not a UTF-8 text file (UTF-16"),
    ("v1.txt", b"1 2\n\xe9 3\n", "is not a UTF-8 text file ("),
    ("v1.txt", "", "v1.txt: not a keypoint table"),
    ("v1.txt", "1 2\n" * (K - 1), "different numbers of landmarks (v0.txt: 8, v1.txt: 7)"),
    ("v1.scf", ("nan " * 6 + "\n") * K, "v1.scf: descriptor row 1 holds a non-finite value"),
    ("v1.scf", ("1 " * 5 + "inf\n") * K, "v1.scf: descriptor row 1 holds a non-finite value"),
    ("v1.scf", "1 2 3\n1 2\n" * (K // 2), "v1.scf: not a numeric table of descriptors (line 2 "
                                          "holds 2 values, line 1 3)"),
    ("v1.scf", "1 2 3 4 5 6\n" * 2 + "a b c 4 5 6\n" * (K - 2),
     "v1.scf: not a numeric table of descriptors (line 3: could not convert string to float: "
     "'a')"),
    ("v1.scf", b"\xff\x00" * 100, "v1.scf: not a numeric table"),
    ("v1.scf", "", "v1.scf: 0 descriptor rows for 8 landmarks"),  # no loadtxt warning
    ("v1.scf", "1 2 3 4 5 6\n" * (K - 1), "v1.scf: 7 descriptor rows for 8 landmarks"),
    ("v1.scf", "1 2 3\n" * K, "v1.scf: descriptors of 3 values but v0.scf has 6"),
], ids=["kp-nan", "kp-all-nan", "kp-inf", "kp-huge", "kp-outside", "kp-3-columns", "kp-text", "kp-binary",
        "kp-utf16", "kp-latin1", "kp-empty", "kp-fewer-rows", "scf-nan", "scf-inf", "scf-ragged", "scf-text-line-3",
        "scf-binary",
        "scf-empty", "scf-fewer-rows", "scf-other-width"])
def test_bad_label_or_descriptor_file(folder, capsys, name, content, needle):
    (folder / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    _fails(capsys, _argv(folder), folder, needle)
    assert not (folder.parent / "run").exists()


def test_labels_on_the_last_pixel_in_either_convention_are_accepted(folder, capsys):
    """1-based labels reach (W, H) (the CMU hotel labels do): not outside the image."""
    pts = np.loadtxt(folder / "v1.txt")
    pts[0] = [W, H]
    pts[1] = [-0.5, -0.5]
    np.savetxt(folder / "v1.txt", pts)
    assert main(_argv(folder)) == 0


def test_too_many_landmarks_is_refused_before_matching(folder, capsys, monkeypatch):
    import pipeline.inputs.landmarks as lio

    monkeypatch.setattr(lio, "MAX_LANDMARKS", K - 1)
    _fails(capsys, _argv(folder), folder, "8 landmarks per image; at most 7")


@pytest.mark.parametrize("damage, extra", [("binary", []), ("truncated", ["--descriptors",
                                                                         "sift"])])
def test_an_image_that_is_not_an_image(folder, capsys, damage, extra):
    """Given descriptors read only the image's header (for its size): a truncated image whose
    header is intact fails once its pixels are needed (SIFT)."""
    png = folder / "v1.png"
    png.write_bytes(png.read_bytes()[:60] if damage == "truncated" else b"\x89PNG" + b"x" * 200)
    _fails(capsys, _argv(folder, *extra), folder, "v1.png: cannot read it as an image")


def test_an_image_that_sees_no_landmark_is_named_with_its_label_file(folder, capsys):
    """Label files named after no image pair with the images by name order (the CMU hotel's
    layout): the refusal of a label file of only 'nan nan' rows named the file alone and said
    to remove "it", so which image to take out with it was left to count."""
    for k in range(4):
        (folder / f"v{k}.txt").rename(folder / f"labels{k + 1}.txt")
        (folder / f"v{k}.scf").rename(folder / f"desc{k + 1}.scf")
    (folder / "labels3.txt").write_text("nan nan\n" * K)
    _fails(capsys, _argv(folder), folder, "labels3.txt: every landmark row is 'nan nan': v2.png, "
           "the image it labels, sees none of them; remove v2.png from the folder with "
           "labels3.txt (and its descriptor file), or label what it sees")


def test_missing_descriptor_file(folder, capsys):
    """The refusal names the image without a descriptor file of its name (it gave the
    counts only: which of 4, or of 101, images lacked one was left to find)."""
    (folder / "v2.scf").unlink()
    _fails(capsys, _argv(folder), folder, "needs one NAME.scf per image (found 3 for 4 images): "
           "v2.png has no v2.scf; give it one, or use --descriptors sift")
    (folder / "v3.scf").unlink()
    _fails(capsys, _argv(folder), folder, "(found 2 for 4 images): v2.png has no v2.scf (2 "
           "images have none)")


@pytest.mark.parametrize("value, kind", [(np.array([["a", "b"]]), "text"),
                                         (np.ones((2, 8)) * (1 + 2j), "complex numbers"),
                                         ({"x": 1.0}, "a struct"),
                                         (np.array([[1.0, "a"]], dtype=object), "a cell array")])
def test_mat_labels_that_are_not_numbers_are_named(folder, capsys, value, kind):
    """A pts_coord of text, complex numbers or a struct: named, not a traceback (complex
    values lost their imaginary part with a numpy warning)."""
    from scipy.io import savemat

    (folder / "v1.txt").unlink()
    savemat(folder / "v1.mat", {"pts_coord": value})
    _fails(capsys, _argv(folder), folder, "v1.mat: pts_coord holds", kind,
           "expected a numeric 2 x K array")


def test_a_broken_label_file_paired_by_order_is_named(folder, capsys):
    """Images and label files paired by name order (the CMU hotel layout: hotel.seq0.png,
    hotel1.txt): a label file broken part-way is named with its line, not counted as missing
    (the message said '4 images but 3 keypoint files')."""
    for k in range(4):
        (folder / f"v{k}.txt").rename(folder / f"labels{k}.txt")
        (folder / f"v{k}.scf").rename(folder / f"labels{k}.scf")
    (folder / "README.txt").write_text("labelled frames, see the paper\n")
    rows = (folder / "labels2.txt").read_text().splitlines()
    rows[4] = "12 34 56"
    (folder / "labels2.txt").write_text("\n".join(rows) + "\n")
    _fails(capsys, _argv(folder), folder, "labels2.txt: not a keypoint table (line 5 is "
                                          "'12 34 56'")


@pytest.mark.parametrize("extra, needle", [
    (("--geometry", "none", "--epipolar-px", "5"),
     "--epipolar-px applies to --geometry epipolar only (this run has --geometry none)"),
    (("--vote-iterations", "3"),
     "--vote-iterations applies to --refine votes only (this run refines by none, the default "
     "of --resolution sync)"),
    (("--resolution", "paper", "--refine", "none", "--vote-iterations", "3"),
     "--vote-iterations applies to --refine votes only (this run refines by none)"),
])
def test_an_option_the_run_would_not_read_is_refused(folder, capsys, extra, needle):
    """--epipolar-px without epipolar matching and --vote-iterations without the votes were
    accepted, ignored and recorded in the report's config as if they had acted."""
    _fails(capsys, _argv(folder, *extra), folder, needle)


def test_vote_iterations_with_the_votes_is_used(folder, capsys):
    assert main(_argv(folder, "--resolution", "paper", "--vote-iterations", "1")) == 0
    report = json.loads((folder.parent / "run" / "report.json").read_text())
    assert report["config"]["vote_iterations"] == 1
    assert report["refinement"]["iterations"] == 1


@pytest.mark.parametrize("first_line, needle", [
    ("x y", "line 1 is 'x y'"),
    ("x,y", "line 1 is 'x,y'"),
    (None, "(3 numbers)"),
    (";", "line 1 is '"),
])
def test_a_label_file_paired_by_order_with_a_header_or_a_third_column_is_named(
        folder, capsys, first_line, needle):
    """Label files paired by name order whose first line is a header ('x y'), whose rows
    hold a third column or are 'x;y': the file is named with its line (the message said '4
    images but 3 keypoint files', or '0 keypoint files' when every file had the header)."""
    for k in range(4):
        (folder / f"v{k}.txt").rename(folder / f"labels{k}.txt")
        (folder / f"v{k}.scf").rename(folder / f"labels{k}.scf")
    (folder / "README.txt").write_text("labelled frames, see the paper\n")
    rows = (folder / "labels1.txt").read_text().splitlines()
    rows = ([r.replace(" ", ";") for r in rows] if first_line == ";" else
            [first_line, *rows] if first_line else [r + " 1" for r in rows])
    (folder / "labels1.txt").write_text("\n".join(rows) + "\n")
    _fails(capsys, _argv(folder), folder, "labels1.txt: not a keypoint table", needle)


def test_a_homography_beside_labels_paired_by_order_is_not_blamed(folder, capsys):
    """A 3 x 3 homography file (three rows of three numbers) is not a label file: with a label
    file missing, the error counts images and label files instead of naming it."""
    for k in range(4):
        (folder / f"v{k}.txt").rename(folder / f"labels{k}.txt")
        (folder / f"v{k}.scf").rename(folder / f"labels{k}.scf")
    (folder / "labels3.txt").unlink()
    (folder / "H1to2p.txt").write_text("1 0 0\n0 1 0\n0 0 1\n")
    err = _fails(capsys, _argv(folder), folder, "4 images but 3 keypoint files")
    assert "H1to2p" not in err


def test_a_label_file_named_after_another_image_than_its_order_gives_is_refused(folder,
                                                                              capsys):
    """Labels paired by name order because one is not named after its image: an image that
    has a label file of its name was silently given the next one (F1 fell to 0.32)."""
    (folder / "v0.txt").rename(folder / "z_v0.txt")  # sorts after v1..v3: order mispairs
    _fails(capsys, _argv(folder), folder, "v1.png has the keypoint file v1.txt by name",
           "gives it v2.txt")


def test_corrupt_mat_labels_are_named(folder, capsys):
    (folder / "v1.txt").unlink()
    (folder / "v1.mat").write_bytes(b"MATLAB 5.0" + bytes(range(256)))
    _fails(capsys, _argv(folder), folder, "v1.mat: not a keypoint table")


# --- the run folder ------------------------------------------------------------------------

@pytest.mark.parametrize("case, needle", [
    ("input", "holds the input DIR"),
    ("parent", "holds the input DIR"),
    ("file-in-input", "is a file"),
    ("file", "is a file"),
    ("devnull", "is a file"),
    ("symlink", "is a symbolic link"),
    ("not-a-run", "is not a formation-match run folder"),
    ("empty", "--out ''"),
])
def test_out_that_is_not_a_new_run_folder(folder, tmp_path, capsys, case, needle):
    other = tmp_path / "other"
    other.mkdir()
    out = {"input": folder, "parent": tmp_path, "file-in-input": folder / "v0.txt",
           "file": other / "f", "devnull": "/dev/null", "symlink": other / "ln",
           "not-a-run": other, "empty": ""}[case]
    if case == "file":
        (other / "f").write_text("precious")
    elif case == "symlink":
        os.symlink(other / "target", other / "ln")
    elif case == "not-a-run":
        (other / "notes.txt").write_text("precious")
    before = tree(tmp_path)
    assert main(_argv(folder, out=out)) == 2
    one_line_error(capsys, needle)
    assert tree(tmp_path) == before
    assert not (other / "target").exists()


def test_out_naming_the_current_folder(folder, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = tree(tmp_path)
    assert main(_argv(folder, out=".")) == 2
    one_line_error(capsys, "is the current folder")
    assert tree(tmp_path) == before


def test_ctrl_c_is_one_line_exit_130_and_nothing_written(folder, capsys, monkeypatch):
    import pipeline.matching.landmarks as lm

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(lm, "match_landmark_edges", interrupted)
    before = tree(folder.parent)
    assert main(_argv(folder)) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("interrupted:") == 1
    assert err.splitlines()[-1].startswith("interrupted: run-landmarks")
    assert tree(folder.parent) == before


@pytest.mark.parametrize("content, needle", [
    ("1,2,3\n" + "1,2\n" * (K - 1), "(line 1 is '1,2,3' (3 numbers);"),
    ("x y\n" + "1 2\n" * (K - 1), "(line 1 is 'x y';"),
    ("", "(no row of two numbers in it;"),
    ("1 2\n" * 3 + "1 2 0.5\n" + "1 2\n" * (K - 4), "(line 4 is '1 2 0.5' (3 numbers);"),
], ids=["comma-3-columns", "header", "empty", "3-columns-line-4"])
def test_a_label_file_paired_by_name_names_its_bad_line(folder, capsys, content, needle):
    """Every image has a label file of its name, one of them is no table: the message names
    the line that is not 'x y' (it said only 'not a keypoint table')."""
    (folder / "v1.txt").write_text(content)
    _fails(capsys, _argv(folder), folder, "v1.txt: not a keypoint table", needle)


def test_an_image_with_two_differing_label_files_is_refused(folder, capsys):
    """v1.txt and a v1.mat of other labels: one of them was used without a word (the .txt);
    two files of the same labels are one."""
    from scipy.io import savemat

    pts = np.loadtxt(folder / "v1.txt")
    savemat(folder / "v1.mat", {"pts_coord": pts.T})
    assert main(_argv(folder)) == 0
    savemat(folder / "v1.mat", {"pts_coord": pts[::-1].T})
    _fails(capsys, _argv(folder), folder, "v1.mat and v1.txt are both keypoint files of v1",
           "keep one of them")


@pytest.mark.parametrize("image, needle", [
    ("v3.webp", "v3.webp is not one of the image formats read"),
    (None, "no image of their name"),
], ids=["unread-format", "no-image"])
def test_a_label_file_without_its_image_is_warned(folder, capsys, image, needle):
    """An image in a format not read (or missing) beside its labels: the run went on with the
    other images and said nothing of the labels it left out."""
    png = folder / "v3.png"
    if image:
        from PIL import Image

        Image.open(png).save(folder / image, lossless=True)
    png.unlink()
    assert main(_argv(folder, "-q")) == 0
    err = capsys.readouterr().err
    assert "1 keypoint file(s) left out, paired with no image (v3.txt)" in err and needle in err


def test_mat_labels_of_no_landmark_are_named_as_such(folder, capsys):
    """pts_coord 2 x 0 in every file: refused as holding no landmark (the message said every
    row was 'nan nan', of a file that has no row)."""
    from scipy.io import savemat

    for k in range(4):
        (folder / f"v{k}.txt").unlink()
        savemat(folder / f"v{k}.mat", {"pts_coord": np.zeros((2, 0))})
    _fails(capsys, _argv(folder), folder, "v0.mat: holds no landmark (pts_coord is 2 x 0)")


def test_a_descriptor_file_named_after_another_image_than_its_order_gives_is_refused(folder,
                                                                                   capsys):
    """Labels paired by name, descriptors by name order because one .scf is not named after
    its image: every image was given the next image's descriptors, without a word."""
    (folder / "v0.scf").rename(folder / "z_v0.scf")  # sorts after v1..v3: order mispairs
    _fails(capsys, _argv(folder), folder, "v1.png has the descriptor file v1.scf by name",
           "gives it v2.scf")


@pytest.mark.parametrize("encode", [
    lambda rows: "\n".join(",".join(r.split()) for r in rows) + "\n",
    lambda rows: "\ufeff" + "\n".join(rows) + "\n",
], ids=["commas", "byte-order-mark"])
def test_descriptor_files_are_read_as_the_label_files_are(folder, capsys, encode):
    """A .scf separated by commas, or saved with a byte-order mark, as a label file may be:
    it was refused ('could not convert string to float: '\\ufeff0'') and now gives the run
    the same descriptors."""
    assert main(_argv(folder)) == 0
    before = json.loads((folder.parent / "run" / "report.json").read_text())["pairwise"]
    rows = (folder / "v1.scf").read_text().splitlines()
    (folder / "v1.scf").write_text(encode(rows), encoding="utf-8")
    assert main(_argv(folder)) == 0
    after = json.loads((folder.parent / "run" / "report.json").read_text())["pairwise"]
    assert after == before


def test_a_descriptor_file_without_its_image_is_warned(folder, capsys):
    """A NAME.scf with no image NAME (its labels gone with it, or never given): the run used
    the other images' descriptors and said nothing of the file it left out."""
    (folder / "v3.png").unlink()
    (folder / "v3.txt").unlink()
    assert main(_argv(folder, "-q")) == 0
    err = capsys.readouterr().err
    assert "1 descriptor file(s) left out, paired with no image (v3.scf)" in err
    assert "no image of their name" in err


@pytest.mark.parametrize("suffix, kind", [(".txt", "keypoint"), (".scf", "descriptor")])
def test_an_image_without_its_own_file_among_named_files_is_refused(folder, capsys, suffix,
                                                                    kind):
    """v2's file renamed (v2b sorts in its place): the other images' files are named after
    them, and name order silently gave v2 the renamed file as if it were its own."""
    (folder / f"v2{suffix}").rename(folder / f"v2b{suffix}")
    _fails(capsys, _argv(folder), folder,
           f"v2.png has no {kind} file of its name, but 3 other image(s) have one (e.g. v0.png)",
           f"gives it v2b{suffix}")


def test_files_named_after_no_image_still_pair_by_name_order(folder, capsys):
    """The documented order pairing (the CMU hotel layout) is kept: no file is named after an
    image."""
    for k in range(4):
        (folder / f"v{k}.txt").rename(folder / f"labels{k}.txt")
        (folder / f"v{k}.scf").rename(folder / f"desc{k}.scf")
    assert main(_argv(folder, "-q")) == 0


def test_a_run_above_the_memory_limit_is_refused_before_the_rule(folder, capsys):
    """run-landmarks had no memory guard: Alg. 1 on the CMU hotel's 101 frames (complete
    graph, descriptors only) took 7.9 GB. The matched links are now counted before the rule
    runs, as resolve counts them, and a run above --max-memory-gb is refused, naming the
    part and the flag; a bad limit is refused before the matching."""
    _fails(capsys, _argv(folder, "--resolution", "paper", "--max-memory-gb", "2e-6"), folder,
           "matched links would need about", "--max-memory-gb")
    _fails(capsys, _argv(folder, "--max-memory-gb", "0"), folder, "--max-memory-gb '0'")
    assert main(_argv(folder, "--resolution", "paper", "--max-memory-gb", "1")) == 0


def test_more_images_than_robot_processes_over_zenoh_is_refused(folder, capsys, monkeypatch):
    """Over zenoh each image is a robot process: a folder of more images than one machine may
    start is refused before the matching, with the count and what to do."""
    from pipeline.runs.transports import zenoh

    monkeypatch.setattr(zenoh, "MAX_ROBOT_PROCESSES", 3)
    before = tree(folder)
    assert main(_argv(folder, "--transport", "zenoh")) == 2
    one_line_error(capsys, "4 images would be 4 processes, at most 3; use --transport sim")
    assert tree(folder) == before and not (folder.parent / "run").exists()
