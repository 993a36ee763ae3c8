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


def test_an_empty_folder_may_become_a_run(tmp_path):
    (tmp_path / "new").mkdir()
    _run(tmp_path / "new", 1)
    assert (tmp_path / "new" / RUN_MARKER).is_file()


def test_without_the_exchange_syscall_the_two_step_swap_works(tmp_path, monkeypatch):
    monkeypatch.setattr(runfolder, "_exchange", lambda a, b: False)
    for k in (1, 2):
        _run(tmp_path / "demo", k)
    assert json.loads((tmp_path / "demo" / "report.json").read_text()) == {"run": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]


def test_a_kill_between_the_two_renames_is_repaired_by_the_next_run(tmp_path, monkeypatch):
    out = tmp_path / "demo"
    _run(out, 1)
    monkeypatch.setattr(runfolder, "_exchange", lambda a, b: False)
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


def test_leftovers_of_dead_runs_are_removed(tmp_path):
    _run(tmp_path / "demo", 1)
    for name in (".demo.tmp-abc", ".demo.old-4242", ".other.tmp-x"):
        (tmp_path / name).mkdir()
    _run(tmp_path / "demo", 2)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.tmp-x", "demo"]


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
