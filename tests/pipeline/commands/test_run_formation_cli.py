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
    ],
)
def test_bad_input_is_a_clear_error(argv, message, capsys, tmp_path):
    out = tmp_path / "run"
    assert main(["run-formation", *argv, "--out", str(out), "--no-rerun"]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err
    assert not out.exists()
