import json

import pytest

from pipeline.runfolder import atomic_run_folder, write_json_atomic


def test_failed_run_keeps_previous(tmp_path):
    out = tmp_path / "runs" / "demo"
    with atomic_run_folder(out) as d:
        write_json_atomic(d / "report.json", {"run": 1})
    with pytest.raises(RuntimeError):
        with atomic_run_folder(out) as d:
            write_json_atomic(d / "report.json", {"run": 2})
            raise RuntimeError("stage failed")
    assert json.loads((out / "report.json").read_text()) == {"run": 1}
    assert sorted(p.name for p in out.parent.iterdir()) == ["demo"]


def test_second_run_replaces_first(tmp_path):
    out = tmp_path / "demo"
    for k in (1, 2):
        with atomic_run_folder(out) as d:
            write_json_atomic(d / "report.json", {"run": k})
    assert json.loads((out / "report.json").read_text()) == {"run": 2}


def test_outputs_are_readable_like_plain_files(tmp_path):
    import os

    mask = os.umask(0o022)
    try:
        with atomic_run_folder(tmp_path / "demo") as d:
            write_json_atomic(d / "report.json", {})
    finally:
        os.umask(mask)
    assert oct((tmp_path / "demo").stat().st_mode & 0o777) == oct(0o755)
    assert oct((tmp_path / "demo" / "report.json").stat().st_mode & 0o777) == oct(0o644)


# ---------------------------------------------------------------- only our own folders, lock, swap

import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402

from pipeline import runfolder  # noqa: E402
from pipeline.errors import InputError  # noqa: E402
from pipeline.outputs import RUN_MARKER  # noqa: E402


def _run(out, k):
    with atomic_run_folder(out) as d:
        write_json_atomic(d / "report.json", {"run": k})


def test_every_run_folder_carries_the_marker_and_nothing_is_left_beside_it(tmp_path):
    _run(tmp_path / "demo", 1)
    assert (tmp_path / "demo" / RUN_MARKER).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]


@pytest.mark.parametrize("content", [".git/HEAD", "photo.jpg"])
def test_a_folder_without_the_marker_is_never_replaced(tmp_path, content):
    out = tmp_path / "mine"
    (out / content).parent.mkdir(parents=True, exist_ok=True)
    (out / content).write_text("precious")
    with pytest.raises(InputError, match="not a formation-match run folder"):
        _run(out, 1)
    assert (out / content).read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine"]


def test_an_empty_folder_may_become_a_run(tmp_path, capsys):
    (tmp_path / "new").mkdir()
    _run(tmp_path / "new", 1)
    assert (tmp_path / "new" / RUN_MARKER).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new"]
    assert capsys.readouterr().err == ""


def test_without_the_exchange_syscall_the_two_step_swap_works(tmp_path, monkeypatch):
    monkeypatch.setattr(runfolder, "_rename2", lambda a, b, flags: False)
    for k in (1, 2):
        _run(tmp_path / "demo", k)
    assert json.loads((tmp_path / "demo" / "report.json").read_text()) == {"run": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]


def test_a_kill_between_the_two_renames_is_repaired_by_the_next_run(tmp_path, monkeypatch):
    out = tmp_path / "demo"
    _run(out, 1)
    monkeypatch.setattr(runfolder, "_rename2", lambda a, b, flags: False)
    real_rename = os.rename

    def killed_after_first(src, dst):
        real_rename(src, dst)
        if ".old-" in str(dst):
            raise KeyboardInterrupt  # the process dies between the two renames

    monkeypatch.setattr(runfolder.os, "rename", killed_after_first)
    with pytest.raises(KeyboardInterrupt):
        _run(out, 2)
    monkeypatch.setattr(runfolder.os, "rename", real_rename)
    assert not out.exists() and list(tmp_path.glob(".demo.old-*"))
    # the next run restores run 1 first; a run that then fails leaves run 1 in place
    with pytest.raises(RuntimeError):
        with atomic_run_folder(out):
            assert json.loads((out / "report.json").read_text()) == {"run": 1}
            raise RuntimeError("stage failed")
    assert json.loads((out / "report.json").read_text()) == {"run": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]


def test_leftovers_of_dead_runs_are_removed(tmp_path, monkeypatch):
    _run(tmp_path / "demo", 1)
    # a run killed while staging (its clean-up never ran) and one killed holding a lock file
    monkeypatch.setattr(runfolder.shutil, "rmtree", lambda *a, **k: None)
    with pytest.raises(KeyboardInterrupt):
        with atomic_run_folder(tmp_path / "demo") as d:
            write_json_atomic(d / "report.json", {"run": "killed"})
            raise KeyboardInterrupt
    monkeypatch.undo()
    fd, _ = runfolder._new_lock(tmp_path / ".demo.lock")
    os.close(fd)  # its process died: the flock is gone, the file stays
    (tmp_path / ".other.tmp-x").mkdir()
    assert len(list(tmp_path.glob(".demo.*"))) == 2
    _run(tmp_path / "demo", 2)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.tmp-x", "demo"]


# ------------------------------------------------- nothing of a user's is ever touched


def _user_entries(tmp_path):
    """A user's folders, files and a link whose names look like a run's siblings."""
    made = {}
    for name in (".demo.tmp-mine", ".demo.old-mine", ".demo.old-1"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "notes.txt").write_text(name)
        made[name + "/notes.txt"] = name
    (tmp_path / ".demo.lock-x").write_text("mine")
    made[".demo.lock-x"] = "mine"
    return made


def _unchanged(tmp_path, made):
    for rel, text in made.items():
        assert (tmp_path / rel).read_text() == text, rel


def test_a_users_entries_named_like_a_runs_siblings_are_never_touched(tmp_path):
    made = _user_entries(tmp_path)
    # a copy of a real run under an old-run name is still the user's (it is not the folder
    # this program made)
    _run(tmp_path / "src", 0)
    import shutil

    shutil.copytree(tmp_path / "src", tmp_path / ".demo.old-copy", symlinks=True)
    made[".demo.old-copy/report.json"] = (tmp_path / "src" / "report.json").read_text()
    for k in (1, 2):  # demo is missing at first: no old-run name is restored in its place
        _run(tmp_path / "demo", k)
        assert json.loads((tmp_path / "demo" / "report.json").read_text()) == {"run": k}
    _unchanged(tmp_path, made)


def test_a_users_lock_file_is_never_replaced_nor_removed(tmp_path):
    (tmp_path / ".demo.lock").write_text("my lock notes")
    with pytest.raises(InputError, match=r"\.demo\.lock.*not a lock file of formation-match"):
        _run(tmp_path / "demo", 1)
    assert (tmp_path / ".demo.lock").read_text() == "my lock notes"
    assert not (tmp_path / "demo").exists()


def test_a_lock_name_that_is_a_link_is_never_written_through(tmp_path):
    target = tmp_path / "precious.txt"
    target.write_text("precious")
    (tmp_path / ".demo.lock").symlink_to(target)
    with pytest.raises(InputError, match="symbolic link"):
        _run(tmp_path / "demo", 1)
    assert target.read_text() == "precious" and (tmp_path / ".demo.lock").is_symlink()
    (tmp_path / ".demo.lock").unlink()
    (tmp_path / ".demo.lock").symlink_to(tmp_path / "nothing-there")  # dangling
    with pytest.raises(InputError, match="symbolic link"):
        _run(tmp_path / "demo", 1)
    assert not (tmp_path / "nothing-there").exists()


@pytest.mark.parametrize("forge", ["text", "copied-marker", "link"])
def test_a_forged_marker_does_not_make_a_folder_replaceable(tmp_path, forge):
    _run(tmp_path / "real", 1)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    marker = mine / RUN_MARKER
    if forge == "text":
        marker.write_text("formation-match run folder: a new run may replace this folder\n")
    elif forge == "copied-marker":
        marker.write_bytes((tmp_path / "real" / RUN_MARKER).read_bytes())
    else:
        marker.symlink_to(tmp_path / "real" / RUN_MARKER)
    with pytest.raises(InputError, match="thesis.tex"):
        _run(mine, 2)
    assert (mine / "thesis.tex").read_text() == "precious"


@pytest.mark.parametrize("change", ["added", "edited", "link"])
def test_a_run_folder_a_user_added_to_is_not_replaced(tmp_path, change):
    out = tmp_path / "demo"
    _run(out, 1)
    if change == "added":
        (out / "sparse").mkdir()
        (out / "sparse" / "my-notes.txt").write_text("mine")
        name = "sparse/my-notes.txt"
    elif change == "edited":
        (out / "report.json").write_text('{"run": 1, "my": "comment"}')
        name = "report.json"
    else:
        (out / "elsewhere").symlink_to(tmp_path)
        name = "elsewhere"
    with pytest.raises(InputError, match=f"{name}.*added or changed after the run wrote it"):
        _run(out, 2)
    assert json.loads((out / "report.json").read_text())["run"] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]


def test_a_second_run_into_the_same_folder_is_refused_at_once(tmp_path):
    out = tmp_path / "demo"
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time\nfrom pipeline.runfolder import claim_run_folder\n"
         f"with claim_run_folder({str(out)!r}):\n    print('held', flush=True)\n"
         "    sys.stdin.readline()\n"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(InputError, match=rf"another run \(pid {holder.pid}\)"):
            _run(out, 1)
    finally:
        holder.communicate("\n", timeout=30)
    _run(out, 2)  # free again once the holder is done
    assert json.loads((out / "report.json").read_text()) == {"run": 2}


def test_a_refused_run_leaves_no_folder_it_made_above_its_own(tmp_path):
    """The default --out (runs/NAME) made runs/ before the input was read; a run refused then
    left it behind, empty. A folder that holds something else stays."""
    out = tmp_path / "runs" / "sub" / "demo"
    with pytest.raises(InputError, match="bad input"):
        with runfolder.claim_run_folder(out):
            raise InputError("bad input")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "keep.txt").write_text("mine")
    with pytest.raises(InputError):
        with runfolder.claim_run_folder(out):
            raise InputError("bad input")
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["keep.txt"]
    _run(out, 1)  # a run that writes its folder keeps the folders above it
    assert json.loads((out / "report.json").read_text()) == {"run": 1}
