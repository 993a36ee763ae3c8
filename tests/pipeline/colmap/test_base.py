"""pipeline.colmap.base: what importing pycolmap through the adapter leaves in the process."""

import signal
import subprocess
import sys


def test_sigterm_after_pycolmap_import_ends_the_process_without_a_stack_dump():
    # pycolmap's import installs glog's failure handler on SIGTERM; a plain kill then printed
    # a C stack trace ("*** Aborted at ...") as if the program had crashed
    code = ("import os, signal, pipeline.colmap.base; "
            "os.kill(os.getpid(), signal.SIGTERM)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == -signal.SIGTERM
    assert "Aborted" not in proc.stderr and "stack trace" not in proc.stderr, proc.stderr
