"""``run-images --spawn`` starts the native viewer bound to this machine's loopback address:
``rr.spawn`` has no bind option, and its viewer took connections (and served the run's
photographs) on every interface, 0.0.0.0:9876."""

import json
import os
import signal
import socket
import sys
import time

import viz.view as view

FAKE = '''
import json, socket, sys
args = sys.argv[1:]
port = int(args[args.index("--port") + 1])
host = args[args.index("--bind") + 1] if "--bind" in args else "0.0.0.0"
s = socket.socket()
s.bind((host, port))
s.listen()
open(sys.argv[0] + ".json", "w").write(json.dumps({"args": args, "pid": __import__("os").getpid()}))
while True:
    s.accept()[0].close()
'''


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_spawned_viewer_listens_on_loopback_only(tmp_path, monkeypatch):
    exe = tmp_path / "rerun"
    exe.write_text(f"#!{sys.executable}\n{FAKE}")
    exe.chmod(0o755)
    monkeypatch.setattr(view, "rerun_executable", lambda: str(exe))
    port = _free_port()
    url = view.spawn_viewer(port, wait_s=20.0)
    seen = tmp_path / "rerun.json"
    try:
        assert url == f"rerun+http://127.0.0.1:{port}/proxy"
        for _ in range(200):
            if seen.exists() and seen.read_text():
                break
            time.sleep(0.05)
        args = json.loads(seen.read_text())["args"]
        assert args[args.index("--bind") + 1] == "127.0.0.1", args
        assert args[args.index("--port") + 1] == str(port), args
        # a viewer already listening takes the stream: no second one is started
        seen.unlink()
        assert view.spawn_viewer(port, wait_s=0.5) == url
        time.sleep(0.3)
        assert not seen.exists()
    finally:
        info = tmp_path / "rerun.json"
        pid = json.loads(info.read_text())["pid"] if info.exists() else None
        for line in os.popen(f"pgrep -f {exe}").read().split():
            os.kill(int(line), signal.SIGKILL)
        if pid:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_a_spawned_live_run_streams_to_the_viewer_spawn_viewer_started(tmp_path,
                                                                         monkeypatch):
    """log_run(live="spawn") starts its viewer through spawn_viewer and streams to the URL it
    returns (here a headless Rerun gRPC server on loopback, no display needed); the file is
    written as well."""
    import subprocess

    from test_rerun_log import make_record

    import viz.rerun_log as rerun_log

    port = _free_port()
    server = subprocess.Popen([view.rerun_executable(), "--serve-grpc", "--port", str(port),
                               "--bind", "127.0.0.1"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        for _ in range(200):
            if view._listening(port):
                break
            time.sleep(0.05)
        calls = []
        monkeypatch.setattr(view, "spawn_viewer",
                            lambda: calls.append(port) or f"rerun+http://127.0.0.1:{port}/proxy")
        path = rerun_log.log_run(tmp_path / "live.rrd", make_record(), live="spawn")
        assert calls == [port] and path.stat().st_size > 0
    finally:
        os.killpg(server.pid, signal.SIGKILL)
        server.wait()
