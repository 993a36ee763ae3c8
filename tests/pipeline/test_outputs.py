"""The output-path guard: nothing a command writes may land on an input, a link, a folder or a
special file, or replace an existing file without --overwrite."""

import os

import pytest

from pipeline.errors import InputError
from pipeline.outputs import check_output_files, check_run_folder, require_input_file


def test_new_file_is_accepted(tmp_path):
    # in a folder still to be made, beside an input still missing: accepted, nothing created
    out = tmp_path / "sub" / "o.csv"
    assert check_output_files([("--out", out)], [("--links", tmp_path / "i")]) is None
    assert sorted(tmp_path.iterdir()) == []


@pytest.mark.parametrize("below", ["x.csv", "sub/x.csv"])
def test_an_output_below_a_file_names_that_file(tmp_path, below):
    """``--out in.csv/x.csv``: one line naming the file that stands where a folder must,
    not the bare OSError 'Not a directory'."""
    (tmp_path / "in.csv").write_text("0,0,1,0\n")
    out = tmp_path / "in.csv" / below
    with pytest.raises(InputError, match=r"--out '.*in.csv/.*x.csv': '.*in.csv' is a file, "
                                         r"not a folder; choose another place"):
        check_output_files([("--out", out)], overwrite=True)


def test_an_empty_output_name_is_named_as_empty():
    """``--out ''``: the message names the empty string, not '.' (what Path('') reads as)."""
    with pytest.raises(InputError, match=r"^--report '' is empty: give the name of a file"):
        check_output_files([("--out", "o.csv"), ("--report", "")])
    with pytest.raises(InputError, match=r"^--links '' is empty: give the file to read"):
        check_output_files([("--out", "o.csv")], [("--links", "")])


def test_existing_file_needs_overwrite(tmp_path):
    (tmp_path / "o.csv").write_text("old")
    with pytest.raises(InputError, match="already exists; pass --overwrite"):
        check_output_files([("--out", tmp_path / "o.csv")])
    check_output_files([("--out", tmp_path / "o.csv")], overwrite=True)


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink", "dotdot"])
def test_output_onto_an_input_is_refused_even_with_overwrite(tmp_path, how):
    src = tmp_path / "in.csv"
    src.write_text("data")
    target = {"same": src, "dotdot": tmp_path / "x" / ".." / "in.csv"}.get(how)
    if how == "symlink":
        (tmp_path / "d").mkdir()
        (tmp_path / "d2").symlink_to(tmp_path)
        target = tmp_path / "d2" / "in.csv"
    if how == "hardlink":
        target = tmp_path / "hard.csv"
        os.link(src, target)
    (tmp_path / "x").mkdir()
    with pytest.raises(InputError, match="is the input file given as --links"):
        check_output_files([("--report", target)], [("--links", src)], overwrite=True)
    assert src.read_text() == "data"


def test_two_outputs_naming_one_file_are_refused(tmp_path):
    with pytest.raises(InputError, match="--out and --report name the same file"):
        check_output_files([("--out", tmp_path / "o"), ("--report", tmp_path / "." / "o")])


def test_symlink_fifo_folder_and_device_are_refused(tmp_path):
    (tmp_path / "real").write_text("x")
    (tmp_path / "link").symlink_to(tmp_path / "real")
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "dir").mkdir()
    for name, what in (("link", "symbolic link"), ("fifo", "not a regular file"),
                       ("dir", "is a folder")):
        with pytest.raises(InputError, match=what):
            check_output_files([("--out", tmp_path / name)], overwrite=True)
    with pytest.raises(InputError, match="not a regular file"):
        check_output_files([("--out", "/dev/null")], overwrite=True)
    assert (tmp_path / "real").read_text() == "x"


def test_read_only_location_is_refused(tmp_path, refuse_writes_in):
    refuse_writes_in(tmp_path)
    with pytest.raises(InputError, match="cannot write in .*Permission denied"):
        check_output_files([("--out", tmp_path / "o.csv")])


def test_a_folder_that_takes_no_file_is_refused_even_for_root():
    # /proc takes no new file, whoever asks (os.access says yes to root): named, not a
    # temporary file's error
    with pytest.raises(InputError, match="--out '/proc/o.csv': cannot write in '/proc'"):
        check_output_files([("--out", "/proc/o.csv")])
    with pytest.raises(InputError, match="cannot write in '/proc'"):
        check_run_folder("/proc/run")


@pytest.mark.parametrize("name", [".", "/", ".."])
def test_run_folder_may_not_be_the_cwd_root_or_a_parent(tmp_path, monkeypatch, name):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match="replaced as a whole"):
        check_run_folder(name)
    with pytest.raises(InputError, match="replaced as a whole"):
        check_run_folder(str(tmp_path))


def test_run_folder_may_not_hold_an_input(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for out in (photos, tmp_path):
        with pytest.raises(InputError, match="holds the input DIR"):
            check_run_folder(out, [("DIR", photos)])
    check_run_folder(photos / "run", [("DIR", photos)])  # a run inside the photo folder is fine


def test_run_folder_may_not_be_a_file_or_a_link(tmp_path):
    (tmp_path / "f").write_text("x")
    (tmp_path / "l").symlink_to(tmp_path / "f")
    with pytest.raises(InputError, match="is a file"):
        check_run_folder(tmp_path / "f")
    with pytest.raises(InputError, match="symbolic link"):
        check_run_folder(tmp_path / "l")


def test_input_file_that_is_a_folder_says_so(tmp_path):
    with pytest.raises(InputError, match="is a folder, not a file"):
        require_input_file(tmp_path, "--links")
    with pytest.raises(InputError, match="no such file"):
        require_input_file(tmp_path / "nope", "--links")
