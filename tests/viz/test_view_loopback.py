"""The web viewer that ``python -m viz.view`` (and ``viz.browser``) starts serves the recording
on this machine's loopback address only."""

import shlex

from rrd_files import write_small_recording

from viz.view import main, viewer_command


def test_the_web_viewer_serves_on_loopback_only(tmp_path, capsys):
    """Rerun serves on every interface (0.0.0.0) unless told: the page and the recording (a
    run's photographs) reached anyone on the network, where the printed URL and the SSH
    port forwarding both go through this machine's own address."""
    cmd = viewer_command(tmp_path / "recording.rrd", web=True)
    assert cmd[cmd.index("--bind") + 1] == "127.0.0.1", cmd
    write_small_recording(tmp_path / "recording.rrd")
    assert main([str(tmp_path), "--web", "--dry-run"]) == 0
    printed = capsys.readouterr().out.strip().splitlines()[-1]
    assert shlex.split(printed)[-2:] == ["--bind", "127.0.0.1"], printed


def test_the_native_viewer_serves_on_loopback_only(tmp_path, capsys):
    """The native viewer also starts a viewer server (for the logging SDK's connections),
    on every interface unless told: it is bound to loopback too."""
    cmd = viewer_command(tmp_path / "recording.rrd", web=False)
    assert cmd[cmd.index("--bind") + 1] == "127.0.0.1", cmd
    write_small_recording(tmp_path / "recording.rrd")
    assert main([str(tmp_path), "--native", "--dry-run"]) == 0
    printed = capsys.readouterr().out.strip().splitlines()[-1]
    assert shlex.split(printed)[-2:] == ["--bind", "127.0.0.1"], printed
