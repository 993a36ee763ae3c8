"""bench/online_cuts.py: its counting wrapper of the history check keeps the engine's signature."""

import json
from pathlib import Path

from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    return load_bench("online_cuts")


def test_a_small_run_saves_one_record_per_hold(tmp_path, capsys):
    out = tmp_path / "cuts"
    assert _bench().main(["--robots", "3", "--graph", "line", "--steps", "4", "--size",
                          "160x120", "--max-features", "60", "--hold", "0", "1",
                          "--out", str(out)]) == 0
    runs = json.loads((out / "results.json").read_text())["runs"]
    assert [r["hold"] for r in runs] == [0, 1]
    assert all(r["online"]["kept"] > 0 for r in runs)
    assert "saved" in capsys.readouterr().out


def test_a_value_the_stage_refuses_is_a_one_line_error(tmp_path, capsys):
    out = tmp_path / "cuts"
    assert _bench().main(["--robots", "3", "--steps", "2", "--hold", "-1", "--size", "160x120",
                          "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: hold -1") and "Traceback" not in err
    assert not out.exists()


def test_the_good_links_cut_online_are_printed_by_reason():
    """They were printed as a raw dict ({'evidence': 2})."""
    by_reason = load_bench("online_cuts")._by_reason
    assert by_reason({"evidence": 2, "history": 1}) == "3 (2 by evidence, 1 by history)"
    assert by_reason({"evidence": 0}) == "0" and by_reason({}) == "0"
