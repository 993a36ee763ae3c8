"""A recording Rerun could not write in full (a full disk, a file-size limit) is an error
naming it, and is not put in place: Rerun's file sink only logs the failure, and the run
put a recording cut short in place and exited 0."""

from __future__ import annotations

import resource
import signal

import pytest
from test_rerun_log import make_record

from viz.rerun_log import log_run


def test_a_recording_cut_by_a_file_size_limit_is_an_error_not_an_output(tmp_path):
    out = tmp_path / "recording.rrd"
    assert signal.getsignal(signal.SIGXFSZ) == signal.SIG_IGN  # a write past it fails: EFBIG
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (4096, hard))
    try:
        with pytest.raises(OSError, match="not written in full") as err:
            log_run(out, make_record())
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    assert err.value.filename == str(out)
    assert list(tmp_path.iterdir()) == []  # neither the cut recording nor its temporary file
    log_run(out, make_record())  # without the limit: written and whole
    assert out.stat().st_size > 4096
