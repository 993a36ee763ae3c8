"""A test run started with SIGINT ignored (in the background of a shell without job control)
failed the tests of what a Ctrl-C does: Python installs no handler of its own then. The test
session takes Python's handler back (tests/conftest.py)."""

import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHECK = ("import signal, sys; sys.path.insert(0, 'tests'); "
         "assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN; import conftest; "
         "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)")


def test_a_session_started_with_sigint_ignored_handles_ctrl_c():
    done = subprocess.run([sys.executable, "-c", CHECK], cwd=ROOT, capture_output=True,
                          text=True, timeout=120,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"
