"""The render memory guard of commands that render the paper's six robots advises only what
they take: a smaller --size, not fewer --robots."""

import pytest

from pipeline.__main__ import main


@pytest.mark.parametrize("argv", [["run-formations", "--out"], ["match-formation"]])
def test_render_memory_advice_names_no_robots_option(argv, capsys, tmp_path):
    args = [*argv, str(tmp_path / "runs")] if "--out" in argv else argv
    assert main([*args, "--size", "4096x4096"]) == 2
    err = capsys.readouterr().err
    assert "rendering and cleaning the views of 6 robots at 4096x4096" in err
    assert "a smaller --size" in err
    assert "--robots" not in err


def test_run_formation_still_advises_fewer_robots(capsys, tmp_path):
    assert main(["run-formation", "--robots", "500", "--graph", "ring",
                 "--out", str(tmp_path / "r")]) == 2
    assert "fewer --robots or a smaller --size" in capsys.readouterr().err
