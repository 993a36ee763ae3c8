"""``make view`` / ``python -m viz.view`` on a folder without a recording said "no
recording.rrd in this folder (was it written with --no-rerun?)" whatever the folder: not what
to do for a run folder written with --no-rerun (python -m viz.saved_run writes its recording),
for an online one (only its run writes it), nor that a folder of resolve's outputs is no run
folder at all (resolve has no --no-rerun)."""

import pytest

from viz.view import main


def _folder(tmp_path, files, dirs=()):
    folder = tmp_path / "run"
    folder.mkdir()
    for name in files:
        (folder / name).write_text("x")
    for name in dirs:
        (folder / name).mkdir()
    return folder


@pytest.mark.parametrize("files, dirs, said", [
    (("report.json", "links.csv"), ("sparse",), "a run folder written with --no-rerun: write "
                                                "its recording with python -m viz.saved_run "),
    (("report.json", "links.csv", "images.csv", "link_steps.csv"), (),
     "an online run folder written with --no-rerun: its recording, on the step timeline, is "
     "written by the run itself; run it again without --no-rerun"),
    (("report.json", "links.csv"), (), "not a run folder"),  # resolve --out / --report
    ((), (), "not a run folder"),  # e.g. a killed run's staging folder, emptied
])
def test_a_folder_without_a_recording_says_what_to_do(tmp_path, capsys, files, dirs, said):
    folder = _folder(tmp_path, files, dirs)
    assert main([str(folder), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {folder}: no recording.rrd in this folder; ") and said in err
    assert err.count("\n") == 1, err
    if "viz.saved_run" in said:  # the command to type, with the folder
        assert f"python -m viz.saved_run {folder}, then open it" in err
