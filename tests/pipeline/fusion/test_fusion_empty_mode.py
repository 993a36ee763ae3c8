"""A run without a track names the fusion mode it ran in: its table said "fixed" (the fixed
100-round scheme) beside the default exact flood, which the stats of an empty stage did not
name."""

import json

from pipeline.__main__ import main


def test_a_run_without_links_names_the_exact_flood(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "run"
    main(["run-formation", "--robots", "2", "--graph", "line", "--size", "64x48",
          "--max-features", "8", "--no-rerun", "--out", str(out)])
    report = json.loads((out / "report.json").read_text())
    assert report["before"]["links"] == 0 and report["fusion"]["tracks"] == 0
    assert report["fusion"]["consensus"] == "exact"
    printed = capsys.readouterr().out
    assert "| fusion rounds (max-c + consensus, exact flood) | 0 (0 + 0) |" in printed
