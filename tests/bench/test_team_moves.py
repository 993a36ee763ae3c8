"""bench/team_moves.py: the central split-and-re-merge move after ``sync`` on the team."""

import json
from pathlib import Path

import numpy as np
from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    return load_bench("team_moves")


def test_the_move_undoes_a_crossing_and_stays_consistent():
    bench = _bench()
    from pipeline.consistency import resolve_conflicts

    case = bench.multiway.team_case(300, seed=0)
    kept = ~resolve_conflicts(case.m, case.edges, case.links, resolution="sync").deleted
    moved, moves = bench.split_and_remerge(case.m, case.links, kept)
    before, after = case.scores(kept), case.scores(moved)
    truth = int((~case.link_good).sum())
    assert before["links_split"] > truth  # sync joins two landmarks' stretches there
    assert moves >= 1 and after["cycle_consistent"]
    assert after["links_split"] <= truth < before["links_split"]
    assert after["f1"] > before["f1"]
    # a move only ever joins more input links: from the truth itself nothing moves
    same, none = bench.split_and_remerge(case.m, case.links, case.link_good)
    assert none == 0 and np.array_equal(same, case.link_good)


def test_it_prints_and_saves_each_team(tmp_path, capsys):
    assert _bench().main(["--n", "60", "--seeds", "1", "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "results.json").read_text())["records"]
    assert [(r["cameras"], r["seed"]) for r in rec] == [(60, 1)]
    assert "60 cameras, seed 1: sync F1" in capsys.readouterr().out


def test_a_team_without_a_quality_auc_prints_a_dash_as_it_saves_null(tmp_path, capsys):
    # two cameras share no triangle: no AUC of the quality, saved null and printed 'nan'
    assert _bench().main(["--n", "2", "--seeds", "0", "--out", str(tmp_path)]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert line.startswith("2 cameras, seed 0:") and line.endswith("quality AUC -")
    assert json.loads((tmp_path / "results.json").read_text())["records"][0]["quality_auc"] is None
