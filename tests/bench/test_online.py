"""bench/online.py: a value the online stage refuses is a one-line error, not a traceback."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_online", ROOT / "bench" / "online.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("args, named", [
    (["--robots", "1"], "n_robots must be an integer >= 2, got 1"),
    (["--robots", "3", "--window", "0"], "window 0"),
    (["--robots", "3", "--steps", "0"], "steps must be an integer >= 1, got 0"),
])
def test_refused_values_are_named_with_exit_status_2(tmp_path, capsys, args, named):
    out = tmp_path / "online"
    assert _bench().main(args + ["--size", "160x120", "--max-features", "60",
                                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and named in err
    assert not (out / "results.json").exists()
