"""match-formation, as a hostile user would run it: a meaningless value is refused before any
rendering with one line on stderr and exit 2; Ctrl-C is one line and exit 130."""

import sys
from pathlib import Path

import pytest

from pipeline.__main__ import main

sys.path.insert(0, str(Path(__file__).parent))
from hostile import one_line_error  # noqa: E402


@pytest.fixture
def no_render(monkeypatch):
    """Rendering is the first piece of work: a case refused 'before any work' never gets there."""
    import data_synth

    def render(*a, **k):
        raise AssertionError("rendered although the arguments are meaningless")

    monkeypatch.setattr(data_synth, "render", render)


@pytest.mark.parametrize("flag,value,message", [
    ("--ratio", "nan", "--ratio nan"),
    ("--ratio", "-1", "(0, 1]"),
    ("--ratio", "5", "--ratio 5.0"),
    ("--threshold-px", "-1", "--threshold-px -1.0"),
    ("--threshold-px", "nan", "--threshold-px nan"),
    ("--threshold-px", "0", "> 0"),
    ("--tol-px", "-1", "--tol-px -1.0"),
    ("--tol-px", "inf", "--tol-px inf"),
    ("--seed", "-5", "--seed -5"),
    ("--size", "100000x100000", "too large"),
    ("--size", "10x10", "at least 64x48"),
    ("--max-features", "3", "at least 8"),
    ("--max-features", "99999999999999999999", "at most 1000000"),
    ("--formation", "z", "--formation 'z'"),
    ("--features", "surf-or-whatever", "--features"),
    # six 4096x4096 views take about 9 GB to render and match (measured 93 bytes per robot
    # and pixel at 2048x1536): refused like run-formation refuses them
    ("--size", "4096x4096", "6 robots at 4096x4096 would need about 9.1 GB"),
    ("--max-memory-gb", "nan", "--max-memory-gb 'nan'"),
])
def test_meaningless_values_are_refused_before_any_work(no_render, capsys, flag, value,
                                                        message):
    assert main(["match-formation", flag, value]) == 2
    one_line_error(capsys, message)


def test_ctrl_c_is_one_line_and_exit_130(monkeypatch, capsys):
    import pipeline.stages as run

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "extract_and_match", interrupted)
    assert main(["match-formation", "--formation", "a", "--size", "160x120"]) == 130
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith("interrupted:") and "Traceback" not in err
