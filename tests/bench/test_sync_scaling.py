"""bench/sync_scaling.py: a case it cannot run is refused before any child starts, and a
relative --data is read from the caller's directory (the children run in the repository)."""

import json
from pathlib import Path

import pytest
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("args, message", [
    (["--cases", "foo"], "--cases foo: expected hotel:F:GRAPH or ring2:N"),
    (["--cases", "ring2:x"], "--cases ring2:x: 'x' is not a count of at least 2 cameras"),
    (["--cases", "hotel:1:ring"], "--cases hotel:1:ring: '1' is not a count of at least 2"),
    (["--cases", "ring2:10", "hotel:6:ring", "--data", "NOPE"], "no such folder of labelled"),
])
def test_a_case_it_cannot_run_is_refused(tmp_path, capsys, args, message):
    (tmp_path / "results.json").write_text('{"previous": true}')
    with pytest.raises(SystemExit) as exc:
        load_bench("sync_scaling").main(args + ["--out", str(tmp_path)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert (tmp_path / "results.json").read_text() == '{"previous": true}'


def test_a_relative_data_folder_is_the_callers(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT / "tests")
    assert load_bench("sync_scaling").main(
        ["--cases", "hotel:6:ring", "--data", "data/cmu_hotel_small", "--out", str(tmp_path)]) == 0
    saved = json.loads((tmp_path / "results.json").read_text())
    assert not (tmp_path / "meta.json").exists()  # one file, replaced at once
    (rec,) = saved["records"]
    assert "load_average" in saved["meta"]
    assert "error" not in rec and rec["cameras"] == 6
