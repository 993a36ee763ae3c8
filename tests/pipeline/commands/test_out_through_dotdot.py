"""An --out that steps out of a missing folder with '..' (``RUN/sub/..``, ``typo/../r9``) is
refused before any work, and no folder is made: the folders made above the run folder were
left behind, ``RUN/sub`` inside the previous run, so that every later run into RUN was
refused."""

import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main
from pipeline.runfolder import atomic_run_folder

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error, tree  # noqa: E402

FAST = ["--size", "160x120", "--max-features", "150", "--no-rerun", "--no-fusion"]


@pytest.fixture
def previous_run(tmp_path):
    run = tmp_path / "r1"
    with atomic_run_folder(run) as tmp:
        (tmp / "report.json").write_text("{}\n")
    return run


def _never(*a, **k):
    raise AssertionError("a run started although --out names no folder")


@pytest.mark.parametrize("extra", [[], ["--steps", "2"]])
def test_out_run_folder_sub_dotdot_leaves_the_previous_run_as_it_was(previous_run, capsys,
                                                                     monkeypatch, extra):
    import pipeline.runs.formation as batch
    import pipeline.runs.online as online

    monkeypatch.setattr(batch, "run_formation", _never)
    monkeypatch.setattr(online, "run_online", _never)
    before = tree(previous_run.parent)
    out = previous_run / "sub" / ".."
    assert main(["run-formation", "--out", str(out), *FAST, *extra]) == 2
    one_line_error(capsys, f"{str(previous_run / 'sub')!r} is no folder",
                   f"e.g. {str(previous_run)!r}")
    assert tree(previous_run.parent) == before
    assert sorted(p.name for p in previous_run.iterdir()) == [".formation-match-run",
                                                                "report.json"]


def test_a_later_run_into_the_folder_is_not_blocked(previous_run, capsys, monkeypatch):
    import pipeline.runs.formation as batch
    from pipeline.runfolder import claim_run_folder

    monkeypatch.setattr(batch, "run_formation", _never)
    assert main(["run-formation", "--out", str(previous_run / "sub" / ".."), *FAST]) == 2
    capsys.readouterr()
    with claim_run_folder(previous_run):  # a run into RUN itself may go on
        pass


@pytest.mark.parametrize("relative", [False, True])
def test_a_missing_folder_before_dotdot_is_not_made(tmp_path, capsys, monkeypatch, relative):
    import pipeline.runs.formation as batch

    monkeypatch.setattr(batch, "run_formation", _never)
    monkeypatch.chdir(tmp_path)
    out = Path("typo", "..", "r9")
    out = out if relative else tmp_path / out
    assert main(["run-formation", "--out", str(out), *FAST]) == 2
    one_line_error(capsys, "is no folder", "'..'")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_file_before_dotdot_is_refused(tmp_path, capsys, monkeypatch):
    import pipeline.runs.formation as batch

    monkeypatch.setattr(batch, "run_formation", _never)
    (tmp_path / "notes.txt").write_text("mine")
    assert main(["run-formation", "--out", str(tmp_path / "notes.txt" / ".." / "r9"),
                 *FAST]) == 2
    one_line_error(capsys, "notes.txt' is no folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_run_formations_out_through_a_missing_folder(tmp_path, capsys, monkeypatch):
    import pipeline.runs.formation as batch

    monkeypatch.setattr(batch, "run_formation", _never)
    assert main(["run-formations", "--out", str(tmp_path / "typo" / ".."), "--size",
                 "160x120", "--max-features", "150"]) == 2
    one_line_error(capsys, "typo' is no folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_dotdot_after_existing_folders_still_names_the_run_folder(previous_run):
    from pipeline.outputs import check_run_folder

    (previous_run.parent / "other").mkdir()
    out = previous_run.parent / "other" / ".." / "r1"
    assert check_run_folder(out) == out
