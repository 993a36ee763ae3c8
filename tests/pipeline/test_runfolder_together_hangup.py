"""A SIGHUP (a closed terminal) while ``publish_together`` puts its run folders in place
(``run-formations``): it was not held as SIGINT and SIGTERM are, so its handler ended the
command between two swaps and only some folders were in place. It is now held, then raised
again once every folder is in place."""

import os
import signal

import pytest

import pipeline.runfolder as runfolder


class HungUp(Exception):
    pass


def _hang_up(signum, frame):
    raise HungUp


def test_a_hangup_while_folders_go_in_place_waits_for_all(tmp_path, monkeypatch):
    swaps = []
    real = runfolder._put_in_place

    def put(staged, out):
        real(staged, out)
        swaps.append(out.name)
        if len(swaps) == 1:  # the terminal closes between the two swaps
            os.kill(os.getpid(), signal.SIGHUP)

    monkeypatch.setattr(runfolder, "_put_in_place", put)
    old = signal.signal(signal.SIGHUP, _hang_up)
    try:
        with pytest.raises(HungUp), runfolder.publish_together():
            for name in ("a", "b"):
                with runfolder.atomic_run_folder(tmp_path / name) as tmp:
                    (tmp / "report.json").write_text(name)
    finally:
        signal.signal(signal.SIGHUP, old)
    assert swaps == ["a", "b"]  # both put in place before the hangup was acted on
    assert (tmp_path / "a" / "report.json").read_text() == "a"
    assert (tmp_path / "b" / "report.json").read_text() == "b"


def test_an_ignored_hangup_stays_ignored(tmp_path, monkeypatch):
    """Under ``nohup`` SIGHUP is ignored: held, it is raised again into the ignore."""
    real = runfolder._put_in_place

    def put(staged, out):
        real(staged, out)
        os.kill(os.getpid(), signal.SIGHUP)

    monkeypatch.setattr(runfolder, "_put_in_place", put)
    old = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with runfolder.publish_together():
            with runfolder.atomic_run_folder(tmp_path / "a") as tmp:
                (tmp / "report.json").write_text("a")
    finally:
        signal.signal(signal.SIGHUP, old)
    assert (tmp_path / "a" / "report.json").read_text() == "a"
