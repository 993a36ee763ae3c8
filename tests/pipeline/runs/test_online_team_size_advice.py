"""An online run over Zenoh with too many frames in a step's window: the advice is what the
run can change (the window), not starting the robots by hand, which an online run's teams,
started step after step by the launching process, cannot be."""

from pipeline.__main__ import main


def test_online_team_too_large_advises_a_shorter_window(capsys, tmp_path):
    out = tmp_path / "run"
    assert main(["run-formation", "--steps", "5", "--robots", "60", "--graph", "ring",
                 "--transport", "zenoh", "--size", "64x48", "--window", "3",
                 "--out", str(out), "--no-rerun"]) == 2
    err = capsys.readouterr().err
    assert "300 frames in a step's window" in err
    assert "use --transport sim, or a shorter --window or --hold" in err
    assert "formation-match robot" not in err
    assert not out.exists()


def test_batch_team_too_large_still_names_robots_on_their_own_hosts(capsys, tmp_path):
    assert main(["run-formation", "--robots", "300", "--graph", "ring", "--transport", "zenoh",
                 "--size", "64x48", "--out", str(tmp_path / "r"), "--no-rerun"]) == 2
    assert "start the robots on their own hosts" in capsys.readouterr().err
