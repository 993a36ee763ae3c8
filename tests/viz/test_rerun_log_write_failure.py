"""A recording Rerun could not write in full (a full disk, a file-size limit) is an error
naming it, and is not put in place: Rerun's file sink only logs the failure, and the run
put a recording cut short in place and exited 0 (viz.rerun_log.check_recording_whole, called
by log_run and log_online before the recording is renamed into place).

The failure is made by cutting a whole recording short, as a failed write leaves it: making
the write itself fail (a file-size limit on the process) can leave Rerun's file sink waiting
forever, which would stall the test run."""

from __future__ import annotations

import pytest
from test_rerun_log import make_record

from viz.rerun_log import check_recording_whole, log_run


def test_a_recording_cut_short_is_an_error_naming_it(tmp_path):
    whole = log_run(tmp_path / "whole.rrd", make_record())
    check_recording_whole(whole, whole)  # written in full: no error
    data = whole.read_bytes()
    for keep in (4096, len(data) // 2, len(data) - 16):
        cut = tmp_path / f"cut-{keep}.rrd"
        cut.write_bytes(data[:keep])
        with pytest.raises(OSError, match="not written in full") as err:
            check_recording_whole(cut, tmp_path / "recording.rrd")
        assert err.value.filename == str(tmp_path / "recording.rrd")
