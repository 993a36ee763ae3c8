"""``make view`` / ``python -m viz.view``: finds the recording, serves the web viewer without a
display, opens any run folder."""

import os

import pytest
from rrd_files import write_small_recording
from test_rerun_log import make_record

from viz.browser import (
    coloured_share,
    find_browser,
    free_port,
    screenshot,
    serve,
    shows_recording,
    stop,
)
from viz.rerun_log import log_run
from viz.view import find_recording, has_display, main, viewer_command, web_url


def test_headless_serves_the_web_viewer_and_prints_the_url(tmp_path, capsys, monkeypatch):
    run = tmp_path / "run"
    run.mkdir()
    write_small_recording(run / "recording.rrd")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("sys.platform", "linux")  # no display variable: no display
    assert main([str(run), "--dry-run"]) == 0
    out = capsys.readouterr().out
    # the page with its data source: the bare http://localhost:9090 opens an empty viewer
    url = "http://localhost:9090/?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A9876%2Fproxy"
    assert f"web viewer: {url}\n" in out and "--web-viewer" in out
    assert "--web-viewer-port 9090 --port 9876" in out  # the ports the URL names
    assert str(run / "recording.rrd") in out
    assert main([str(run), "--dry-run", "--port", "8000", "--grpc-port", "8001"]) == 0
    out = capsys.readouterr().out
    assert web_url(8000, 8001) in out and "--web-viewer-port 8000 --port 8001" in out


def test_display_starts_the_native_viewer():
    assert has_display({"DISPLAY": ":0"}, "linux") and not has_display({}, "linux")
    cmd = viewer_command(os.path.join("a", "recording.rrd"), web=False)
    assert "--web-viewer" not in cmd and cmd[1].endswith("recording.rrd")


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
    (runs / "c" / "report.json").write_text("{}")  # a file, but no recording
    assert main([str(runs / "c" / "report.json"), "--dry-run"]) == 2
    assert "not a Rerun recording (.rrd)" in capsys.readouterr().err


def test_the_printed_url_shows_the_recording_in_a_headless_browser(tmp_path):
    if find_browser() is None:
        pytest.skip("no Chromium on this machine (Debian: apt-get install chromium): the web "
                    "viewer's URL is not opened in a browser")
    path = log_run(tmp_path / "recording.rrd", make_record())
    port, grpc_port = free_port(), free_port()
    server = serve(path, port, grpc_port)
    try:
        shown = screenshot(web_url(port, grpc_port), timeout_s=90)
        # the same page without its data source: the empty viewer the check must refuse
        bare = screenshot(f"http://localhost:{port}", timeout_s=8)
    finally:
        stop(server)
    assert shows_recording(shown), f"{coloured_share(shown):.2%} of the views area coloured"
    assert not shows_recording(bare), f"{coloured_share(bare):.2%} of the views area coloured"


def test_the_newest_recording_is_a_finished_runs_not_a_staging_folders(tmp_path):
    """A run writes its folder in a hidden staging folder beside it
    (pipeline.runfolder.atomic_run_folder), which a killed run leaves behind: make view
    opened that newer, unfinished recording instead of the last run's."""
    import os

    runs = tmp_path / "runs"
    for name, mtime in (("formation-d", 1_000), (".formation-d.tmp-x1y2", 2_000),
                        ("sub/.hidden", 3_000)):
        (runs / name).mkdir(parents=True)
        (runs / name / "recording.rrd").write_bytes(b"x")
        os.utime(runs / name / "recording.rrd", (mtime, mtime))
    assert find_recording(None, runs) == runs / "formation-d" / "recording.rrd"


def test_a_folder_of_several_recordings_or_runs_names_them(tmp_path):
    """clean-db writes OUT.rrd beside OUT.db, so a folder of cleaned databases holds several
    recordings, and run-formations' --out holds four run folders: neither was written with
    --no-rerun, which is what the message said; it names what the folder holds instead."""
    cleaned = tmp_path / "cleaned"
    cleaned.mkdir()
    for name in ("castle.db", "castle.rrd", "graffiti.db", "graffiti.rrd"):
        (cleaned / name).write_bytes(b"x")
    with pytest.raises(FileNotFoundError) as exc:
        find_recording(cleaned)
    assert "2 recordings in this folder ('castle.rrd', 'graffiti.rrd')" in str(exc.value)
    assert "--no-rerun" not in str(exc.value)
    with pytest.raises(FileNotFoundError, match=r"its recording is .*castle\.rrd"):
        find_recording(cleaned / "castle.db")

    runs = tmp_path / "runs"
    for name in "abcde":
        (runs / f"formation-{name}").mkdir(parents=True)
        (runs / f"formation-{name}" / "recording.rrd").write_bytes(b"x")
    with pytest.raises(FileNotFoundError) as exc:
        find_recording(runs)
    assert ("a folder of 5 runs ('formation-a', 'formation-b', 'formation-c', 'formation-d' "
            "and 1 more)") in str(exc.value)


@pytest.mark.parametrize("ports, message", [
    (["--port", "70000"], "error: --port 70000: give a TCP port from 1 to 65535\n"),
    (["--grpc-port", "0"], "error: --grpc-port 0: give a TCP port from 1 to 65535\n"),
    (["--port", "9876"], "error: --port and --grpc-port are both 9876: the page and the "
                         "recording need a port each, e.g. --port 9876 --grpc-port 9877\n"),
])
def test_web_viewer_ports_it_cannot_serve_on_are_refused(tmp_path, capsys, monkeypatch, ports,
                                                         message):
    """--port 70000 printed a URL on port 70000, then rerun refused the port; one port for
    both printed a URL whose recording never loaded (rerun: 'port is already used')."""
    run = tmp_path / "run"
    run.mkdir()
    write_small_recording(run / "recording.rrd")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("sys.platform", "linux")  # no display variable: no display
    assert main([str(run), "--dry-run", *ports]) == 2
    captured = capsys.readouterr()
    assert captured.err == message and "web viewer:" not in captured.out
    assert main([str(run), "--dry-run", "--native", *ports]) == 0  # no port is served


def test_a_landmarks_run_folder_is_named_not_asked_about_no_rerun(tmp_path):
    """run-landmarks writes no recording and has no --no-rerun option."""
    run = tmp_path / "lm"
    run.mkdir()
    (run / "report.json").write_text('{"feature_landmarks": []}')
    with pytest.raises(FileNotFoundError) as exc:
        find_recording(run)
    assert "a run-landmarks run folder" in str(exc.value)
    assert "--no-rerun" not in str(exc.value)


@pytest.mark.parametrize("module", ["viz.view", "viz.browser"])
def test_help_states_what_opens_without_a_path(module, capsys):
    """--help listed RUN_DIR|FILE.rrd with no word (it opens the newest runs/**/recording.rrd
    when left out) and --web / --native without which is the default."""
    import importlib
    import re

    with pytest.raises(SystemExit):
        importlib.import_module(module).main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "default: the newest recording.rrd under runs/" in text
    if module == "viz.view":
        assert re.search(r"--web serve the web viewer .*the default without a display", text)
        assert re.search(r"--native start the native viewer \(the default on a machine with a "
                         r"display\)", text)
