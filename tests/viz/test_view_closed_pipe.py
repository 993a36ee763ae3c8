"""``python -m viz.view --dry-run --web | head -1``: the reader gone after the first line,
the next print ended the program in a BrokenPipeError traceback, exit code 1; so did
``python -m viz.saved_run RUN | head -1`` once the recording was written."""

import os
import subprocess
import sys
from pathlib import Path

from rrd_files import write_small_recording
from test_rerun_log import make_record
from test_saved_run import _save

ROOT = Path(__file__).resolve().parents[2]


def _run_into_a_closed_pipe(args):
    read_end, write_end = os.pipe()
    os.close(read_end)  # as head does after its line: every write to the pipe fails
    try:
        return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, stdout=write_end,
                              stderr=subprocess.PIPE, text=True)
    finally:
        os.close(write_end)


def test_a_reader_that_stopped_reading_ends_the_printing_quietly(tmp_path):
    run = tmp_path / "formation-d"
    run.mkdir()
    write_small_recording(run / "recording.rrd")
    done = _run_into_a_closed_pipe(["viz.view", "--dry-run", "--web", str(run)])
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 0


def test_saved_run_writes_its_recording_and_ends_quietly(tmp_path):
    out = _save(make_record(), tmp_path / "run")
    done = _run_into_a_closed_pipe(["viz.saved_run", str(out)])
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 0
    assert (out / "recording.rrd").stat().st_size > 0
