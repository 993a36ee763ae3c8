"""``python -m viz.saved_run`` on run-formations' --out (a folder of runs) or on a folder of
clean-db / clean-h5 outputs said only 'no report.json; not a run folder'; it now names the
runs to give, or the recording the folder already holds."""

import shlex

from rrd_files import write_small_recording

from viz.saved_run import main


def test_a_folder_of_runs_names_them(tmp_path, capsys):
    for name in ("formation-a", "formation-b", ".formation-c.tmp-x"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "report.json").write_text("{}")
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.endswith("; a folder of 2 runs ('formation-a', 'formation-b'): give one of "
                        "them\n"), err
    assert not (tmp_path / "recording.rrd").exists()


def test_a_folder_of_cleaning_outputs_names_its_recording(tmp_path, capsys):
    folder = tmp_path / "clean out"
    folder.mkdir()
    (folder / "out.links.csv").write_text("cam_i,feat_i,cam_j,feat_j,status,reason,round\n")
    rrd = write_small_recording(folder / "out.rrd")
    assert main([str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.endswith(f"open it with make view RUN={shlex.quote(str(rrd))}\n"), err
    assert err.count("\n") == 1
