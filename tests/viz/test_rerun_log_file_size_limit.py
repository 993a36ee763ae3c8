"""A recording that cannot be written (a full disk, a file-size limit) ends the command with an
error naming it, every time: written through Rerun's file sink, the failed write was only
logged and the sink could then block for ever in ``disconnect`` (about one run in five under
a 64 KB limit never ended). The recording is now written by this process
(viz.rerun_log.record_to_memory / write_recording), so the write's own error is raised.

Each attempt runs in a process of its own under RLIMIT_FSIZE, with a timeout: a hang is a
failure, not a stalled test run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import resource, signal, sys
sys.path[:0] = [sys.argv[2], sys.argv[3]]
from test_rerun_log import make_record
from viz.rerun_log import log_run
record = make_record()
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead
resource.setrlimit(resource.RLIMIT_FSIZE, (64 * 1024, 64 * 1024))
try:
    log_run(sys.argv[1], record)
except OSError as e:
    print(f"OSError|{e.filename}|{e}")
    sys.exit(3)
print("written")
"""


def test_a_recording_past_a_file_size_limit_is_an_error_every_time(tmp_path):
    target = tmp_path / "recording.rrd"
    target.write_bytes(b"the previous run's recording")
    for attempt in range(6):
        try:
            done = subprocess.run([sys.executable, "-c", SCRIPT, str(target), str(ROOT),
                                   str(ROOT / "tests" / "viz")], cwd=ROOT, capture_output=True,
                                  text=True, timeout=90)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"attempt {attempt}: the recording's write never ended") from None
        assert done.returncode == 3, (attempt, done.stdout, done.stderr[-2000:])
        _, filename, message = done.stdout.strip().splitlines()[-1].split("|", 2)
        assert filename == str(target)
        assert "could not be written" in message and "File too large" in message
        assert target.read_bytes() == b"the previous run's recording"
        assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.rrd"]  # no temp file
