"""viz.saved_run killed while it writes a run folder's recording leaves nothing in the folder:
its temporary recording was left inside, a file the run did not write, and every later run
into that --out was refused."""

from __future__ import annotations

import signal
import subprocess
import sys

from test_rerun_log import make_record
from test_saved_run_replaced_meanwhile import _run_folder

from pipeline.outputs import run_folder_problem
from pipeline.runfolder import atomic_run_folder

_KILLED = """
import os, signal, sys
import viz.rerun_log
from viz.saved_run import log_run_folder

def killed(sink, path):  # the recording is written, not yet in place
    os.kill(os.getpid(), signal.SIGKILL)

viz.rerun_log.check_recording_whole = killed
log_run_folder(sys.argv[1])
"""


def test_a_killed_recording_leaves_the_folder_replaceable(tmp_path):
    run = _run_folder(tmp_path / "run", make_record(), "first")
    done = subprocess.run([sys.executable, "-c", _KILLED, str(run)], capture_output=True)
    assert done.returncode == -signal.SIGKILL, done.stderr
    assert run_folder_problem(run) is None
    with atomic_run_folder(run) as staged:  # the next run into it
        (staged / "report.json").write_text("{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing left beside it
