"""``python -m viz.view --dry-run`` prints the viewer's command as a shell reads it: a run
folder whose path holds a space or a quote was printed bare, and the pasted command opened
other files."""

import shlex

import pytest
from rrd_files import write_small_recording

from viz.view import main, viewer_command


@pytest.mark.parametrize("name", ["my runs", "it's", "a\"b", "$HOME"])
@pytest.mark.parametrize("mode", ["--web", "--native"])
def test_the_printed_command_splits_back_into_the_command(tmp_path, capsys, name, mode):
    run = tmp_path / name / "formation-d"
    run.mkdir(parents=True)
    write_small_recording(run / "recording.rrd")
    assert main([str(run), "--dry-run", mode]) == 0
    printed = capsys.readouterr().out.splitlines()[-1]
    assert shlex.split(printed) == viewer_command(run / "recording.rrd", web=mode == "--web")
