"""bench/consistency_scale.py: arguments it cannot run, and a missing matplotlib, are refused
before any work, with a one-line message and exit status 2."""

import importlib.util
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    return load_bench("consistency_scale")


@pytest.mark.parametrize("args, message", [
    (["--n", "6", "1"], "--n 1: a team has at least 2 robots"),
    (["--n", "6", "--repeat", "0"], "argument --repeat: '0': expected a whole number of at least 1"),
])
def test_bad_arguments_are_refused(tmp_path, capsys, args, message):
    out = tmp_path / "scale"
    with pytest.raises(SystemExit) as exc:
        _bench().main(args + ["--features", "50", "--out", str(out)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_a_missing_matplotlib_is_named_before_the_runs(tmp_path, capsys, monkeypatch):
    mod = _bench()
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "matplotlib" else find_spec(name, *a))
    out = tmp_path / "scale"
    with pytest.raises(SystemExit) as exc:
        mod.main(["--n", "2", "--repeat", "1", "--features", "50", "--out", str(out)])
    assert exc.value.code == 2
    captured = capsys.readouterr()
    assert "matplotlib is missing" in captured.err
    assert captured.out == "" and not out.exists()
