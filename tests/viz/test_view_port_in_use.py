"""``python -m viz.view --web`` with a port another program (an earlier viewer) holds: the URL
was printed, then rerun stopped with 'Address already in use' (naming no port when it was the
recording's); the port is now named before anything is served."""

import socket

import pytest
from rrd_files import write_small_recording

import viz.view as view
from viz.browser import free_port


@pytest.mark.parametrize("flag", ["--port", "--grpc-port"])
def test_a_port_in_use_is_named_before_serving(tmp_path, capsys, monkeypatch, flag):
    monkeypatch.setattr(view, "run_viewer", lambda cmd: pytest.fail("viewer started"))
    run = tmp_path / "run"
    run.mkdir()
    write_small_recording(run / "recording.rrd")
    with socket.socket() as held:
        held.bind((view.LOOPBACK, 0))
        held.listen()
        busy = held.getsockname()[1]
        ports = {"--port": free_port(), "--grpc-port": free_port(), flag: busy}
        args = [str(run), "--web", "--port", str(ports["--port"]),
                "--grpc-port", str(ports["--grpc-port"])]
        assert view.main(args) == 2
        captured = capsys.readouterr()
        assert captured.err.startswith(f"error: {flag} {busy}: the port is in use")
        assert captured.err.count("\n") == 1 and "web viewer:" not in captured.out
        assert view.main([*args, "--dry-run"]) == 0  # a dry run serves nothing
