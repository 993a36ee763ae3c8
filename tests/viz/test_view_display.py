"""How ``python -m viz.view`` chooses between the native and the web viewer."""

import subprocess

import pytest

import viz.view as view


@pytest.fixture
def run(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "recording.rrd").write_bytes(b"RRF2")
    return tmp_path / "run"


def test_native_without_a_display_is_refused_before_the_viewer_starts(run, capsys, monkeypatch):
    """--native on Linux without DISPLAY / WAYLAND_DISPLAY started the native viewer, which
    failed with its own log lines (winit: neither WAYLAND_DISPLAY nor DISPLAY is set) and
    exit status 1; now one 'error:' line, exit 2, and no viewer."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(view.sys, "platform", "linux")
    monkeypatch.setattr(subprocess, "call", lambda cmd: pytest.fail(f"started {cmd}"))
    assert view.main([str(run), "--native"]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("error: --native needs a display")
    assert captured.err.count("\n") == 1 and "opening" not in captured.out
    assert view.main([str(run), "--native", "--dry-run"]) == 0  # prints the command only


def test_native_with_a_display_starts_it(run, monkeypatch):
    monkeypatch.setenv("DISPLAY", ":0")
    started = []
    monkeypatch.setattr(subprocess, "call", lambda cmd: started.append(cmd) or 0)
    assert view.main([str(run)]) == 0
    assert started and "--web-viewer" not in started[0]
