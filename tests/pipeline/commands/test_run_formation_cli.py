"""run-formation's bad input: a clear message and exit code 2 before any stage runs."""

import pytest

from pipeline.__main__ import main


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--formation", "z"], "unknown formation 'z'"),
        (["--size", "12"], "expected WIDTHxHEIGHT"),
        (["--size", "32x20"], "at least 64x48"),
        (["--features", "bogus"], "unknown feature method 'bogus'"),
        (["--robots", "5"], "--robots and --graph go together"),
        (["--max-features", "3"], "at least 8"),
        (["--formation", "a", "--robots", "4", "--graph", "ring"],
         "--formation a with --robots/--graph: those render a parametric formation"),
        (["--steps", "2", "--formation", "b", "--robots", "3", "--graph", "ring"],
         "--formation b with --robots/--graph"),
        (["--robots", "300", "--graph", "ring", "--transport", "zenoh", "--size", "64x48"],
         "300 robots would be 300 processes, at most 256"),
        (["--steps", "5", "--robots", "60", "--graph", "ring", "--transport", "zenoh",
          "--size", "64x48", "--window", "3"],
         "300 frames in a step's window"),
    ],
)
def test_bad_input_is_a_clear_error(argv, message, capsys, tmp_path):
    out = tmp_path / "run"
    assert main(["run-formation", *argv, "--out", str(out), "--no-rerun"]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err
    assert not out.exists()


def test_a_parametric_formation_is_titled_by_its_robots_and_graph(tmp_path):
    """--robots/--graph render no formation a-d: the report does not call it 'formation d'."""
    import json

    out = tmp_path / "p"
    assert main(["run-formation", "--robots", "3", "--graph", "line", "--size", "160x120",
                 "--max-features", "100", "--no-fusion", "--no-rerun", "--out", str(out)]) == 0
    title = json.loads((out / "report.json").read_text())["title"]
    assert title == "3 robots on a line graph (seed 0)"


@pytest.mark.parametrize("window, warned", [(1, True), (2, False)])
def test_switching_with_a_window_of_one_step_is_warned(window, warned, capsys, tmp_path):
    """--switching-topology forces every link up once every --window steps: with --window 1
    the graph never switches, which the user is told."""
    import json

    out = tmp_path / "run"
    assert main(["run-formation", "--steps", "1", "--robots", "2", "--graph", "line",
                 "--switching-topology", "--window", str(window), "--size", "160x120",
                 "--max-features", "80", "--no-fusion", "--no-rerun", "--quiet",
                 "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert ("--switching-topology with --window 1" in err) == warned
    if warned:  # the warning says what the run did: every link up
        assert json.loads((out / "report.json").read_text())["steps"][0]["comm_edges"] == \
            [[0, 1]]
