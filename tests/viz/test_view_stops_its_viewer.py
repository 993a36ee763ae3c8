"""viz.view: a ``kill PID`` (SIGTERM) or a closed terminal (SIGHUP) of ``python -m viz.view``
stops the viewer it started; the rerun server lived on and held the web viewer's ports."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: viz.view running a stand-in viewer (a process that would sleep for a minute)
WRAPPER = ("import subprocess, sys\n"
           "from viz import view\n"
           "real = subprocess.Popen\n"
           "def popen(cmd, **kw):\n"
           "    proc = real(cmd, **kw)\n"
           "    print(proc.pid, flush=True)\n"
           "    return proc\n"
           "subprocess.Popen = popen\n"
           "sys.exit(view.run_viewer([sys.executable, '-c', 'import time; time.sleep(60)']))\n")


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_to_the_wrapper_stops_the_viewer(sig):
    proc = subprocess.Popen([sys.executable, "-c", WRAPPER], cwd=ROOT, stdout=subprocess.PIPE,
                            text=True)
    viewer = int(proc.stdout.readline())
    time.sleep(0.2)
    proc.send_signal(sig)
    assert proc.wait(timeout=30) == 128 + sig
    t0 = time.monotonic()
    while _running(viewer) and time.monotonic() - t0 < 10:
        time.sleep(0.05)
    alive = _running(viewer)
    if alive:
        os.kill(viewer, signal.SIGKILL)
    assert not alive


def test_the_viewers_own_status_is_returned():
    from viz.view import run_viewer

    assert run_viewer([sys.executable, "-c", "raise SystemExit(3)"]) == 3
