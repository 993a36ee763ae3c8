"""A Ctrl-C whose KeyboardInterrupt Python dropped (its handler ran within a call whose error
Python clears, as a SIGTERM's can be: tests/pipeline/test_errors_dropped_kill.py) let the
command run to its end and exit 0, as if no one had asked it to stop. It now ends as a dropped
SIGTERM does: one line ``interrupted: …`` naming what is in place, exit 130."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent("""
    import os, signal, sys
    from pipeline.errors import exit_quietly_on_interrupt, run_interruptibly
    exit_quietly_on_interrupt("prog")

    def run():
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except BaseException:  # what the C code does with it
            pass
        return 0

    sys.exit(run_interruptibly("prog", run))
""")

#: ``python -m pipeline ARGS`` whose ``data_synth.render`` sends it a SIGINT and drops the
#: KeyboardInterrupt, as a call that clears errors would
DROPPED_IN_RENDER = textwrap.dedent("""
    import os, signal, sys
    from pipeline.errors import clean_up_on_terminate, exit_quietly_on_interrupt
    exit_quietly_on_interrupt("formation-match")
    clean_up_on_terminate()
    import data_synth
    real = data_synth.render

    def render(*args, **kwargs):
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except BaseException:
            pass
        return real(*args, **kwargs)

    data_synth.render = render
    sys.argv = ["formation-match", *sys.argv[1:]]
    from pipeline.__main__ import entry
    entry()
""")


def test_a_ctrl_c_whose_exception_was_dropped_still_ends_as_interrupted():
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert (done.returncode, done.stderr) == (
        130, "interrupted: prog stopped, nothing was written or replaced\n")


def test_run_formation_interrupted_while_rendering_exits_130(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "out"
    out.mkdir()
    done = subprocess.run([sys.executable, "-c", DROPPED_IN_RENDER, "run-formation",
                           "--formation", "a", "--size", "160x120", "--max-features", "100",
                           "--no-rerun", "--no-fusion", "--out", str(out / "run")], cwd=ROOT,
                          env={**os.environ, "TMPDIR": str(tmp)}, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 130, done.stderr
    # too late to stop it: the run ran to its end, and the line says what is in place
    assert done.stderr.endswith(
        f"interrupted: run-formation stopped; already in place, complete: "
        f"'{out / 'run'}'\n"), done.stderr
    assert sorted(p.name for p in out.iterdir()) == ["run"]
    assert sorted(p.name for p in tmp.iterdir()) == []
