"""A command started with stdout closed (``>&-``, a daemon or cron job): Python sets
``sys.stdout`` to None, and the program's exit ended a finished run in an AttributeError
traceback ('NoneType' object has no attribute 'flush') and exit code 1."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_run_with_stdout_closed_ends_with_its_exit_code(tmp_path):
    links = tmp_path / "links.csv"
    links.write_text("0,0,1,0\n1,0,2,0\n")
    out = tmp_path / "out.csv"
    done = subprocess.run(["sh", "-c", 'exec "$@" >&-', "sh", sys.executable, "-m", "pipeline",
                           "resolve", "--links", str(links), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert out.read_text().count("\n") == 3  # the header and both links
