"""A run killed while it deletes the previous run it has just replaced (or a dead run's
leftover) leaves a folder the next run removes: the previous run's folder, swapped to the
staging name, lost its marker first and kept the rest (a whole run's files, e.g. 0.5 MB of
run-images --sequence) beside the run folder for good."""

import os

import pytest

from pipeline import runfolder


class _Killed(BaseException):
    """Stands for a SIGKILL: nothing after it runs."""


def _run(out, text):
    with runfolder.atomic_run_folder(out) as tmp:
        for name in ("links.csv", "report.json", "recording.rrd"):
            (tmp / name).write_text(text)
        (tmp / "sparse").mkdir()
        for name in ("cameras.bin", "images.bin", "points3D.bin"):
            (tmp / "sparse" / name).write_text(text)


@pytest.mark.parametrize("after", range(8))
def test_a_kill_while_the_previous_run_is_deleted_leaves_nothing_after_the_next(
        tmp_path, monkeypatch, after):
    out = tmp_path / "run"
    _run(out, "first")
    unlink = os.unlink
    count = [0]

    def killed_after(*args, **kwargs):
        if count[0] == after:
            raise _Killed
        count[0] += 1
        return unlink(*args, **kwargs)

    monkeypatch.setattr(os, "unlink", killed_after)
    try:
        _run(out, "second")
    except _Killed:
        pass
    monkeypatch.setattr(os, "unlink", unlink)
    assert (out / "report.json").read_text() == "second"  # in place before the deletion
    _run(out, "third")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    assert (out / "report.json").read_text() == "third"
