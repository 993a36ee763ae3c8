"""The forked feature workers end with the run that forked them: run-images killed (SIGKILL)
while its COLMAP SIFT workers ran left them behind for good, blocked on their pipe to it."""

import os
import signal
import subprocess
import sys
import textwrap
import time

_KILLED_PARENT = textwrap.dedent("""
    import multiprocessing, os, signal, time
    from concurrent.futures import ProcessPoolExecutor
    from pipeline.errors import die_with_parent

    pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("fork"),
                               initializer=die_with_parent, initargs=(os.getpid(),))
    worker = pool.submit(os.getpid).result()
    print(worker, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
""")


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[-1].split()[0] != "Z"
    except OSError:
        return False


def test_a_worker_ends_when_its_run_is_killed():
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_PARENT], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, cwd=os.getcwd())
    worker = int(proc.stdout.readline())
    proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    try:
        deadline = time.monotonic() + 10
        while _alive(worker) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _alive(worker)
    finally:
        if _alive(worker):
            os.kill(worker, signal.SIGKILL)
