"""viz.view on a run folder whose relative path starts with '-' (``run-formation --out=-r1``):
the viewer read the recording's path as an option ("error: unexpected argument '-r' found")
and opened nothing."""

import os

from viz.view import viewer_command


def test_a_path_starting_with_a_dash_is_no_option_of_the_viewer(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for web in (True, False):
        cmd = viewer_command(os.path.join("-r1", "recording.rrd"), web=web)
        assert cmd[1] == os.path.join(".", "-r1", "recording.rrd")
        assert not any(a.startswith("-r") for a in cmd)
    assert viewer_command("runs/r1/recording.rrd", web=False)[1] == "runs/r1/recording.rrd"
