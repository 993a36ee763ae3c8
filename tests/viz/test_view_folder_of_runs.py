"""``python -m viz.view`` on the parent of run folders: the runs it lists are the ones it
would open, not the hidden staging folder of a run killed before its folder was in place."""

from rrd_files import write_small_recording

from viz.view import main


def _run(parent, name):
    (parent / name).mkdir(parents=True)
    write_small_recording(parent / name / "recording.rrd")
    return parent / name


def test_a_killed_runs_staging_folder_is_not_listed_as_a_run(tmp_path, capsys):
    """A killed run leaves '.fd.tmp-…' holding a recording beside the run folders: it was
    listed as a run ('a folder of 2 runs ('.fd.tmp-abcdefgh', 'fd')'), and alone as the one
    run to give, though the newest recording under runs/ leaves hidden folders out."""
    _run(tmp_path, ".fd.tmp-abcdefgh")
    _run(tmp_path, "fd")
    assert main([str(tmp_path), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {tmp_path}: a folder of 1 run ('fd'): give the run to open\n", err
    (tmp_path / "fd" / "recording.rrd").unlink()
    (tmp_path / "fd").rmdir()
    assert main([str(tmp_path), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert ".fd.tmp-" not in err and "not a run folder" in err, err


def test_several_runs_are_counted(tmp_path, capsys):
    for name in ("formation-a", "formation-b"):
        _run(tmp_path, name)
    assert main([str(tmp_path), "--dry-run"]) == 2
    assert "a folder of 2 runs ('formation-a', 'formation-b')" in capsys.readouterr().err
