"""``python -m viz.view`` on a recording cut short (a copy or download not finished, a full
disk): the viewer showed the part before the cut, without the layout or the report, and the
header alone as an empty viewer, with no error; such a file is now refused, named."""

import pytest
from rrd_files import write_small_recording

from viz.view import main


@pytest.mark.parametrize("keep", ["half", "header"])
def test_a_recording_cut_short_is_refused(tmp_path, capsys, monkeypatch, keep):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    whole = write_small_recording(tmp_path / "whole.rrd").read_bytes()
    run = tmp_path / "run"
    run.mkdir()
    cut = run / "recording.rrd"
    cut.write_bytes(whole[:len(whole) // 2] if keep == "half" else whole[:4])
    for target in (cut, run):
        assert main([str(target), "--dry-run"]) == 2
        captured = capsys.readouterr()
        assert captured.err.startswith(f"error: {cut}: a recording cut short"), captured.err
        assert captured.err.count("\n") == 1 and "opening" not in captured.out
    assert main([str(tmp_path / "whole.rrd"), "--dry-run"]) == 0
