"""An --out (or the default runs/formation-d) under a symbolic link that leads nowhere (a
'runs' linked to a drive not mounted) is refused with what is wrong: the message was
'runs: File exists'."""

import os
import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main
from pipeline.outputs import check_run_folder

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error  # noqa: E402

FAST = ["--size", "160x120", "--max-features", "150"]


def _never(*a, **k):
    raise AssertionError("a run started although its --out cannot be made")


@pytest.fixture
def dangling_runs(tmp_path, monkeypatch):
    import pipeline.runs.formation as batch
    import pipeline.runs.online as online

    monkeypatch.setattr(batch, "run_formation", _never)
    monkeypatch.setattr(online, "run_online", _never)
    monkeypatch.chdir(tmp_path)
    target = tmp_path / "drive" / "runs"
    os.symlink(target, tmp_path / "runs")
    return target


@pytest.mark.parametrize("argv", [
    ["run-formation", *FAST],
    ["run-formation", *FAST, "--steps", "2"],
    ["run-formation", *FAST, "--out", "runs/mine/d"],
    ["run-formations", *FAST],
])
def test_a_link_leading_nowhere_is_named(dangling_runs, capsys, argv):
    assert main(argv) == 2
    one_line_error(capsys, "/runs' is a symbolic link that leads nowhere",
                   f"(to {str(dangling_runs)!r})", "create or mount its target")
    assert os.readlink("runs") == str(dangling_runs)
    assert not dangling_runs.parent.exists()


def test_once_its_target_exists_the_folder_is_accepted(dangling_runs):
    dangling_runs.mkdir(parents=True)
    assert check_run_folder(Path("runs", "formation-d")) == Path("runs", "formation-d")
