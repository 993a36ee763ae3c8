"""How ``python -m viz.view`` chooses between the native and the web viewer."""


import pytest
from rrd_files import write_small_recording

import viz.view as view


@pytest.fixture
def run(tmp_path):
    (tmp_path / "run").mkdir()
    write_small_recording(tmp_path / "run" / "recording.rrd")
    return tmp_path / "run"


def test_native_without_a_display_is_refused_before_the_viewer_starts(run, capsys, monkeypatch):
    """--native on Linux without DISPLAY / WAYLAND_DISPLAY started the native viewer, which
    failed with its own log lines (winit: neither WAYLAND_DISPLAY nor DISPLAY is set) and
    exit status 1; now one 'error:' line, exit 2, and no viewer."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(view.sys, "platform", "linux")
    monkeypatch.setattr(view, "run_viewer", lambda cmd: pytest.fail(f"started {cmd}"))
    assert view.main([str(run), "--native"]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("error: --native needs a display")
    assert captured.err.count("\n") == 1 and "opening" not in captured.out
    assert view.main([str(run), "--native", "--dry-run"]) == 0  # prints the command only


def test_native_with_a_display_starts_it(run, monkeypatch):
    monkeypatch.setenv("DISPLAY", ":0")
    started = []
    monkeypatch.setattr(view, "run_viewer", lambda cmd: started.append(cmd) or 0)
    assert view.main([str(run)]) == 0
    assert started and "--web-viewer" not in started[0]


@pytest.mark.parametrize("platform", ["darwin", "win32"])
def test_macos_and_windows_open_the_native_viewer_without_display_variables(platform):
    """macOS and Windows set no DISPLAY: make view served the web viewer there and printed
    an SSH tunnel to use, on a desktop with a screen. Their native viewer is used unless the
    session is a remote shell."""
    assert view.has_display({}, platform)
    assert not view.has_display({"SSH_CONNECTION": "10.0.0.2 50000 10.0.0.1 22"}, platform)
    assert not view.has_display({"SSH_TTY": "/dev/ttys001"}, platform)


@pytest.mark.parametrize("platform", ["linux", "freebsd14"])
def test_linux_and_bsd_need_a_display_variable(platform):
    assert not view.has_display({}, platform)
    assert view.has_display({"DISPLAY": ":0"}, platform)
    assert view.has_display({"WAYLAND_DISPLAY": "wayland-0"}, platform)
