"""``make view`` / ``python -m viz.view``: finds the recording, serves the web viewer without a
display, opens any run folder."""

import os

import pytest

from viz.view import find_recording, has_display, main, viewer_command


def test_headless_serves_the_web_viewer_and_prints_the_url(tmp_path, capsys, monkeypatch):
    run = tmp_path / "run"
    run.mkdir()
    (run / "recording.rrd").write_bytes(b"x")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main([str(run), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "http://localhost:9090" in out and "--web-viewer" in out
    assert str(run / "recording.rrd") in out


def test_display_starts_the_native_viewer():
    assert has_display({"DISPLAY": ":0"}) and not has_display({})
    cmd = viewer_command(os.path.join("a", "recording.rrd"), web=False)
    assert "--web-viewer" not in cmd and cmd[-1].endswith("recording.rrd")


def test_newest_recording_and_missing_ones(tmp_path, capsys):
    runs = tmp_path / "runs"
    for k, name in enumerate(("a", "b")):
        (runs / name).mkdir(parents=True)
        f = runs / name / "recording.rrd"
        f.write_bytes(b"x")
        os.utime(f, (1000 + k, 1000 + k))
    assert find_recording(None, runs) == runs / "b" / "recording.rrd"
    with pytest.raises(FileNotFoundError, match="run 'make run-formation' first"):
        find_recording(None, tmp_path / "empty")
    (runs / "c").mkdir()
    assert main([str(runs / "c"), "--dry-run"]) == 2
    assert "no recording.rrd" in capsys.readouterr().err
