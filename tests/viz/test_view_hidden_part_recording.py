"""``python -m viz.view FOLDER`` leaves out the hidden temporary ``.rrd`` a killed ``clean-db``
or ``clean-h5`` leaves beside its outputs (``.OUT.PID-…part.rrd``, often empty)."""

from rrd_files import write_small_recording

from viz.view import main

PART = ".out.10819-4227179-a07825ff-f2d22f680f0d.part.rrd"


def test_a_killed_commands_temporary_recording_is_not_opened(tmp_path, capsys):
    """Alone it was opened ('…part.rrd: an empty file; give a run folder', though a folder
    was given); beside the previous OUT.rrd the folder was said to hold two recordings."""
    (tmp_path / PART).write_bytes(b"")
    assert main([str(tmp_path), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert PART not in err and "no recording.rrd in this folder" in err, err
    write_small_recording(tmp_path / "out.rrd")
    assert main([str(tmp_path), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"opening {tmp_path / 'out.rrd'}\n") and PART not in out, out
