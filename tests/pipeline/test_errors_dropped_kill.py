"""pipeline.errors.run_interruptibly: a SIGTERM whose exception Python dropped (its handler ran
within a call whose error Python clears: seen once in eight kills of clean-db, while a module
it imported defined a ``Callable[...]`` alias) let the command run to its end and exit 0, as if
no one had asked it to stop. It now ends with the ``terminated: …`` line and 143."""

import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent("""
    import os, signal, sys
    from pipeline.errors import clean_up_on_terminate, run_interruptibly
    clean_up_on_terminate()

    def run():
        try:
            os.kill(os.getpid(), signal.SIGTERM)
        except BaseException:  # what the C code does with it
            pass
        return 0

    sys.exit(run_interruptibly("prog", run))
""")


def test_a_kill_whose_exception_was_dropped_still_ends_as_terminated():
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert (done.returncode, done.stderr) == (
        143, "terminated: prog stopped, nothing was written or replaced\n")


def test_a_run_without_a_kill_keeps_its_code():
    code = textwrap.dedent("""
        import sys
        from pipeline.errors import clean_up_on_terminate, run_interruptibly
        clean_up_on_terminate()
        sys.exit(run_interruptibly("prog", lambda: 3))
    """)
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert (done.returncode, done.stderr) == (3, "")
