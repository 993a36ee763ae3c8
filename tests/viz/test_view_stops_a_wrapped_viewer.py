"""viz.view: a ``kill PID`` of ``python -m viz.view`` stops the viewer binary, not only the
``rerun`` command it ran. That command (the Python package's wrapper) starts the binary as its
child: the wrapper was stopped, the binary lived on and held the web viewer's ports."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: a stand-in for the ``rerun`` wrapper: it starts the "viewer" (a minute's sleep) as its own
#: child, prints that child's pid and waits for it, as ``rerun_cli`` does
WRAPPED = ("import subprocess, sys\n"
           "viewer = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
           "print(viewer.pid, flush=True)\n"
           "sys.exit(viewer.wait())\n")
PROGRAM = ("import sys\n"
           "from viz import view\n"
           f"sys.exit(view.run_viewer([sys.executable, '-c', {WRAPPED!r}]))\n")


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def test_a_kill_of_viz_view_stops_the_viewer_the_wrapper_started():
    proc = subprocess.Popen([sys.executable, "-c", PROGRAM], cwd=ROOT, stdout=subprocess.PIPE,
                            text=True)
    viewer = int(proc.stdout.readline())
    time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 128 + signal.SIGTERM
    t0 = time.monotonic()
    while _running(viewer) and time.monotonic() - t0 < 10:
        time.sleep(0.05)
    alive = _running(viewer)
    if alive:
        os.kill(viewer, signal.SIGKILL)
    assert not alive
