"""run-formations, as a hostile user would run it: a meaningless value is refused before any
formation is rendered, with one line on stderr and exit 2, and nothing is written."""

import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error  # noqa: E402


@pytest.mark.parametrize("flag,value,message", [
    ("--seed", "-5", "--seed -5"),
    ("--size", "100000x100000", "too large"),
    ("--max-features", "99999999999999999999", "at most 1000000"),
    ("--max-features", "3", "at least 8"),
])
def test_meaningless_values_are_refused_before_any_work(tmp_path, monkeypatch, capsys, flag,
                                                        value, message):
    import pipeline.run as run

    def never(*a, **k):
        raise AssertionError("a formation ran although the arguments are meaningless")

    monkeypatch.setattr(run, "run_formation", never)
    out = tmp_path / "runs"
    assert main(["run-formations", "--out", str(out), flag, value]) == 2
    one_line_error(capsys, message)
    assert not out.exists()
