"""A SIGTERM (``kill PID``, ``timeout``) to a command ends it through its clean-up, as a Ctrl-C
does: it died at once, leaving ``colmap-read-*`` (a copy of the database) or ``fm-team-*`` in
the temporary folder and ``.OUT.lock`` beside the output, at every kill. Now: one line
``terminated: … stopped …``, exit status 143, nothing left but the input."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TERMINATED = 128 + 15  # the exit status of a command stopped by SIGTERM

#: ``python -m pipeline ARGS`` (what it runs first, then its entry point), which sends itself a
#: SIGTERM right after ``module.function`` has run
KILLED_AFTER = textwrap.dedent("""
    import importlib, os, signal, sys
    from pipeline.errors import clean_up_on_terminate, exit_quietly_on_interrupt
    exit_quietly_on_interrupt("formation-match")
    clean_up_on_terminate()
    module, name = sys.argv[1].rsplit(".", 1)
    owner = importlib.import_module(module)
    real = getattr(owner, name)

    def then_killed(*args, **kwargs):
        out = real(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)
        return out

    setattr(owner, name, then_killed)
    sys.argv = ["formation-match", *sys.argv[2:]]
    from pipeline.__main__ import entry
    entry()
""")


def _killed_run(tmp_path, after: str, *argv: str) -> tuple[subprocess.CompletedProcess, Path]:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    done = subprocess.run([sys.executable, "-c", KILLED_AFTER, after, *argv], cwd=ROOT,
                          env={**os.environ, "TMPDIR": str(tmp)}, capture_output=True,
                          text=True, timeout=60)
    return done, tmp


def test_sigterm_while_clean_db_reads_the_database_leaves_nothing(tmp_path):
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
                            str(src), "--out", str(out / "o.db"), "--no-rerun")
    assert (done.returncode, done.stderr) == (
        TERMINATED, "terminated: clean-db stopped, nothing was written or replaced\n")
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
