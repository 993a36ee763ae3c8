"""A process forked by a run (a pool of feature workers) does not hold the run folder's lock:
run-images killed while its forked COLMAP SIFT workers ran left them blocked for good, holding
the lock, and every later run into that --out was refused ('being written by another run',
naming the dead pid)."""

import os
import signal
import subprocess
import sys
import textwrap

from pipeline.runfolder import claim_run_folder

_KILLED_RUN = textwrap.dedent("""
    import os, signal, sys, time
    from pipeline.runfolder import claim_run_folder
    with claim_run_folder(sys.argv[1]):
        child = os.fork()
        if child == 0:  # a worker that outlives its run
            null = os.open(os.devnull, os.O_RDWR)
            os.dup2(null, 1)
            os.dup2(null, 2)
            time.sleep(60)
            os._exit(0)
        print(child, flush=True)
        os.kill(os.getpid(), signal.SIGKILL)
""")


def test_a_worker_outliving_its_killed_run_does_not_hold_the_lock(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-c", _KILLED_RUN, str(out)], capture_output=True,
                          text=True, timeout=120, cwd=os.getcwd())
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    worker = int(proc.stdout.strip())
    try:
        os.kill(worker, 0)  # still alive
        with claim_run_folder(out):
            pass
        assert sorted(p.name for p in tmp_path.iterdir()) == []  # the dead run's lock removed
    finally:
        os.kill(worker, signal.SIGKILL)
