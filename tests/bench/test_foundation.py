"""bench/foundation.py: a size, formation or feature method it cannot run is a one-line error
with exit status 2, not a traceback, and no results file is written."""

from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    return load_bench("foundation")


@pytest.mark.parametrize("args", [["--size", "160"], ["--size", "axb"]])
def test_a_size_that_is_not_width_x_height_is_refused(tmp_path, capsys, args):
    out = tmp_path / "found"
    with pytest.raises(SystemExit) as exc:
        _bench().main(args + ["--repeat", "1", "--out", str(out)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "expected WIDTHxHEIGHT" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("args, message", [
    (["--methods", "bogus"], "unknown feature method 'bogus'"),
    (["--formation", "zz"], "unknown formation 'zz'"),
])
def test_a_method_or_formation_the_pipeline_refuses_is_named(tmp_path, capsys, args, message):
    out = tmp_path / "found"
    assert _bench().main(args + ["--size", "160x120", "--max-features", "50", "--repeat", "1",
                                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {message}") and "Traceback" not in err
    assert not out.exists()


def test_an_unknown_method_is_refused_before_the_known_ones_run(tmp_path, capsys, monkeypatch):
    bench = _bench()
    ran = []
    monkeypatch.setattr(bench, "bench_method", lambda m, *a: ran.append(m))
    out = tmp_path / "found"
    assert bench.main(["--methods", "orb,bogus", "--size", "160x120", "--repeat", "1",
                       "--out", str(out)]) == 2
    assert ran == [] and "unknown feature method 'bogus'" in capsys.readouterr().err
