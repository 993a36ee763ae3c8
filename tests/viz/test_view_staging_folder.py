"""``python -m viz.view`` and ``python -m viz.saved_run`` on a run's staging folder
``.NAME.tmp-*`` (a run writing NAME, or one killed before putting it in place): the viewer
opened its recording, half-written while the run writes it, and ``viz.saved_run`` called it
'not a run folder' or wrote a recording into it; both now name the run folder to give."""

from rrd_files import write_small_recording

from pipeline.runfolder import staging_beside
from viz.saved_run import main as saved_run_main
from viz.view import main as view_main


def test_a_staging_folder_names_its_run_folder(tmp_path, capsys):
    run = tmp_path / "formation-d"
    run.mkdir()
    write_small_recording(run / "recording.rrd")
    with staging_beside(run) as staging:
        write_small_recording(staging / "recording.rrd")
        before = sorted(p.name for p in tmp_path.iterdir())
        for main, target, extra in ((view_main, staging, ["--dry-run"]),
                                    (view_main, staging / "recording.rrd", ["--dry-run"]),
                                    (saved_run_main, staging, [])):
            assert main([str(target), *extra]) == 2
            err = capsys.readouterr().err
            assert err.startswith(f"error: {target}: ") and err.count("\n") == 1, err
            assert f"the staging folder of the run folder {run}:" in err, err
        assert sorted(p.name for p in tmp_path.iterdir()) == before  # no lock, no recording
        assert sorted(p.name for p in staging.iterdir()) == [".formation-match-run",
                                                             "recording.rrd"]
    assert view_main([str(run), "--dry-run"]) == 0
