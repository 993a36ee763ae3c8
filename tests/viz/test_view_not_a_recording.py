"""``python -m viz.view`` on a ``.rrd`` file that is not a recording: the viewer served an
empty page with no error and kept serving; the file is now refused before the viewer starts."""

import pytest
from test_rerun_log import make_record

from viz.rerun_log import log_run
from viz.view import main


@pytest.mark.parametrize("content, said", [(b"", "an empty file"),
                                           (b"not a recording\n", "not a Rerun recording"),
                                           (b"PK\x03\x04zip", "not a Rerun recording")])
def test_a_rrd_that_is_not_a_recording_is_refused(tmp_path, capsys, monkeypatch, content, said):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    bad = tmp_path / "bad.rrd"
    bad.write_bytes(content)
    run = tmp_path / "run"
    run.mkdir()
    (run / "recording.rrd").write_bytes(content)
    for target in (bad, run):
        assert main([str(target), "--dry-run"]) == 2
        captured = capsys.readouterr()
        assert captured.err.startswith(f"error: {target}") and said in captured.err
        assert captured.err.count("\n") == 1 and "opening" not in captured.out


def test_a_written_recording_is_opened(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    path = log_run(tmp_path / "recording.rrd", make_record(n_cams=2, size=(32, 24)))
    assert main([str(path), "--dry-run"]) == 0
    assert f"opening {path}" in capsys.readouterr().out


def test_a_fifo_or_folder_named_rrd_is_refused_not_read(tmp_path, capsys, monkeypatch):
    """A FIFO named *.rrd in a run folder was opened and read: the program blocked for ever
    (and rerun with it); a folder named *.rrd was handed to the viewer."""
    import os

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    fifo_run = tmp_path / "fifo-run"
    fifo_run.mkdir()
    os.mkfifo(fifo_run / "a.rrd")
    dir_run = tmp_path / "dir-run"
    (dir_run / "recording.rrd").mkdir(parents=True)
    for target in (fifo_run, dir_run):
        assert main([str(target), "--dry-run"]) == 2
        err = capsys.readouterr().err
        assert "not a regular file" in err and err.count("\n") == 1, err
