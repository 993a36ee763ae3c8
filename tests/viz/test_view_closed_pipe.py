"""``python -m viz.view --dry-run --web | head -1``: the reader gone after the first line,
the next print ended the program in a BrokenPipeError traceback, exit code 1."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_reader_that_stopped_reading_ends_the_printing_quietly(tmp_path):
    run = tmp_path / "formation-d"
    run.mkdir()
    (run / "recording.rrd").write_bytes(b"RRF2")
    read_end, write_end = os.pipe()
    os.close(read_end)  # as head does after its line: every write to the pipe fails
    try:
        done = subprocess.run([sys.executable, "-m", "viz.view", "--dry-run", "--web", str(run)],
                              cwd=ROOT, stdout=write_end, stderr=subprocess.PIPE, text=True)
    finally:
        os.close(write_end)
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 0
