"""A SIGTERM (``kill PID``, ``timeout``) to a command ends it through its clean-up, as a Ctrl-C
does: it died at once, leaving ``colmap-read-*`` (a copy of the database) or ``fm-team-*`` in
the temporary folder and ``.OUT.lock`` beside the output, at every kill. Now: one line
``terminated: … stopped …``, exit status 143, nothing left but the input."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TERMINATED = 128 + 15  # the exit status of a command stopped by SIGTERM

#: ``python -m pipeline ARGS`` (what it runs first, then its entry point), which sends itself a
#: SIGTERM (or the signal named by KILL_WITH) right after ``module.function`` has run
KILLED_AFTER = textwrap.dedent("""
    import importlib, os, signal, sys
    # as started from a terminal: under nohup (a CI job) SIGHUP is ignored, and stays so
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    from pipeline.errors import clean_up_on_terminate, exit_quietly_on_interrupt
    exit_quietly_on_interrupt("formation-match")
    clean_up_on_terminate()
    module, name = sys.argv[1].rsplit(".", 1)
    owner = importlib.import_module(module)
    real = getattr(owner, name)

    def then_killed(*args, **kwargs):
        out = real(*args, **kwargs)
        os.kill(os.getpid(), getattr(signal, os.environ.get("KILL_WITH", "SIGTERM")))
        return out

    setattr(owner, name, then_killed)
    sys.argv = ["formation-match", *sys.argv[2:]]
    from pipeline.__main__ import entry
    entry()
""")


def _killed_run(tmp_path, after: str, *argv: str,
                signal_name: str = "SIGTERM") -> tuple[subprocess.CompletedProcess, Path]:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    done = subprocess.run([sys.executable, "-c", KILLED_AFTER, after, *argv], cwd=ROOT,
                          env={**os.environ, "TMPDIR": str(tmp), "KILL_WITH": signal_name},
                          capture_output=True, text=True, timeout=60)
    return done, tmp


@pytest.mark.parametrize(("signal_name", "status"), [("SIGTERM", TERMINATED),
                                                     ("SIGHUP", 128 + 1)])
def test_sigterm_while_clean_db_reads_the_database_leaves_nothing(tmp_path, signal_name,
                                                                  status):
    """And a SIGHUP (the terminal closed), which killed it as a SIGTERM did."""
    src = tmp_path / "in" / "in.db"
    src.parent.mkdir()
    subprocess.run([sys.executable, "-c", "import sys; sys.path.insert(0, 'tests/pipeline/commands'); "
                    "from test_clean_db import _db_with_planted_conflicts as make; "
                    "make(sys.argv[1])", str(src)], cwd=ROOT, check=True, timeout=60)
    out = tmp_path / "out"
    out.mkdir()
    # killed once the database's snapshot is read (it lives in the temporary folder), after
    # pycolmap's import: its glog handler on SIGTERM must not take the signal either
    done, tmp = _killed_run(tmp_path, "pipeline.colmap.database._contents", "clean-db",
                            str(src), "--out", str(out / "o.db"), "--no-rerun",
                            signal_name=signal_name)
    assert (done.returncode, done.stderr) == (
        status, "terminated: clean-db stopped, nothing was written or replaced\n")
    assert sorted(p.name for p in tmp.iterdir()) == []
    assert sorted(p.name for p in out.iterdir()) == []


def test_sigterm_while_a_team_starts_leaves_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    # killed once the team's folder is written and the observer listens, before the robots
    done, tmp = _killed_run(tmp_path, "pipeline.team.launcher.write_team", "run-formation",
                            "--size", "160x120", "--max-features", "100", "--no-rerun",
                            "--robots", "3", "--graph", "ring", "--transport", "zenoh",
                            "--out", str(out / "run"))
    assert done.returncode == TERMINATED, done.stderr
    assert done.stderr.endswith(
        "terminated: run-formation stopped, nothing was written or replaced\n"), done.stderr
    assert sorted(p.name for p in tmp.iterdir()) == []
    assert sorted(p.name for p in out.iterdir()) == []
