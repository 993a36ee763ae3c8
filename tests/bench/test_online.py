"""bench/online.py: a value the online stage refuses is a one-line error, not a traceback."""

import json
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    return load_bench("online")


@pytest.mark.parametrize("args, named", [
    (["--robots", "1"], "n_robots must be an integer >= 2, got 1"),
    (["--robots", "3", "--window", "0"], "window must be an integer >= 1, got 0"),
    (["--robots", "3", "--steps", "0"], "steps must be an integer >= 1, got 0"),
])
def test_refused_values_are_named_with_exit_status_2(tmp_path, capsys, args, named):
    out = tmp_path / "online"
    assert _bench().main(args + ["--size", "160x120", "--max-features", "60",
                                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and named in err
    assert not (out / "results.json").exists()


@pytest.mark.parametrize("previous", ['{"runs": [', "[1, 2]", '{"runs": [{"x": 1}]}'])
def test_a_results_file_it_cannot_extend_is_refused_before_the_runs(tmp_path, capsys,
                                                                    previous):
    out = tmp_path / "online"
    out.mkdir()
    (out / "results.json").write_text(previous)
    assert _bench().main(["--robots", "3", "--graph", "ring", "--steps", "2", "--size",
                          "160x120", "--max-features", "60", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"error: {out / 'results.json'}: not")
    assert "Traceback" not in captured.err and captured.out == ""  # no run started
    assert (out / "results.json").read_text() == previous


def test_sizes_run_apart_share_one_results_file(tmp_path, capsys):
    out = tmp_path / "online"
    for n in ("3", "2"):
        assert _bench().main(["--robots", n, "--graph", "ring", "--steps", "2", "--size",
                              "160x120", "--max-features", "60", "--out", str(out)]) == 0
    runs = json.loads((out / "results.json").read_text())["runs"]
    assert [r["summary"]["robots"] for r in runs] == [2, 3]


def test_a_batch_step_beyond_the_run_is_refused(tmp_path, capsys):
    out = tmp_path / "online"
    with pytest.raises(SystemExit) as exc:
        _bench().main(["--robots", "3", "--steps", "2", "--batch-steps", "7", "--size",
                       "160x120", "--max-features", "60", "--out", str(out)])
    assert exc.value.code == 2
    assert "--batch-steps 7: the run has steps 1 to 2" in capsys.readouterr().err
    assert not out.exists()
