"""The report of a run-formation job names each resolution rule's own cuts: with a fault flag
the evidence rule gives way to the fault-tolerant Alg. 1, and ``resolution_quality`` must
then file what ran under ``paper``, not under the rule that was asked for."""

import csv
import json

from pipeline.faults import FaultConfig
from pipeline.runs.formation import FormationConfig, run_formation

SMALL = dict(formation="d", seed=11, size=(161, 97), fusion=False, rerun=False,
             resolution="evidence")


def _run(tmp_path, name, faults=None):
    out = tmp_path / name
    run_formation(FormationConfig(**SMALL, faults=faults, out=str(out)))
    report = json.loads((out / "report.json").read_text())
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return report, rows


def test_resolution_quality_files_the_rule_that_ran_under_its_own_name(tmp_path, monkeypatch):
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    clean, _ = _run(tmp_path, "clean")
    faulty, rows = _run(tmp_path, "faulty", FaultConfig(delay_rounds=1))
    assert clean["resolution"]["method"] == "evidence"
    assert faulty["resolution"]["method"] == "paper"
    q, q_clean = faulty["resolution_quality"], clean["resolution_quality"]
    # this input is one where the two rules cut differently
    assert q_clean["paper"] != q_clean["evidence"]
    # what ran (Alg. 1, read back from links.csv) is filed under paper ...
    cut = [r for r in rows if r["reason"] == "resolution"]
    assert q["paper"]["good_cut"] == sum(r["truth"] == "1" for r in cut)
    assert q["paper"]["spurious_cut"] == sum(r["truth"] == "0" for r in cut)
    assert q["paper"]["pairwise_f1"] == faulty["pairwise"]["after_resolution"]["f1"]
    # ... and the evidence rule's row is the evidence rule's own cut of the same links
    assert q["evidence"] == q_clean["evidence"]


def test_a_team_of_robots_without_a_graph_kind_is_titled_by_its_comm_edges(tmp_path, monkeypatch):
    """A hand-written formation team gives robots but no data.graph: the observer's report (the
    config of formation_config_of) names the robots' comm edges, not a 'None graph'."""
    from pipeline.runs.observe import formation_config_of
    from pipeline.team.teamfile import parse_team

    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    team = parse_team({
        "version": 1, "name": "hand", "comm_edges": [[0, 1], [1, 2]],
        "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7100 + i}"} for i in range(3)],
        "data": {"kind": "formation", "formation": "a", "robots": 3, "size": [161, 97]},
        "options": {"max_features": 200}})
    out = tmp_path / "observed"
    config = formation_config_of(team, out, rerun=False)
    assert config.robots == 3 and config.graph is None
    run_formation(config)
    report = json.loads((out / "report.json").read_text())
    n_edges = len(report["comm_edges"])
    assert report["title"] == f"3 robots on {n_edges} comm edges (seed 0)"


def test_a_parametric_run_records_no_formation_letter(tmp_path, monkeypatch):
    """--robots/--graph draw the graph; config.formation said 'd', which no parametric run
    uses (--formation d beside --robots is refused): it is null, a lettered run's stays."""
    from pipeline.__main__ import main

    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "line"
    assert main(["run-formation", "--robots", "3", "--graph", "line", "--size", "161x97",
                 "--max-features", "100", "--no-fusion", "--no-rerun", "--out", str(out)]) == 0
    config = json.loads((out / "report.json").read_text())["config"]
    assert config["formation"] is None and config["robots"] == 3 and config["graph"] == "line"
    clean, _ = _run(tmp_path, "lettered")
    assert clean["config"]["formation"] == "d"


def test_the_report_records_the_merge_radius_the_keypoints_were_merged_at(tmp_path,
                                                                          monkeypatch):
    """Without --merge-radius, config.merge_radius was null and the radius the run merged its
    keypoints at (the rule's: 2 px with evidence, 0.5 px with paper) was written nowhere."""
    from pipeline.consistency.rules import get_rule

    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    report, _ = _run(tmp_path, "radius")
    assert report["config"]["merge_radius"] is None
    assert report["config"]["merge_radius_used_px"] == get_rule("evidence").merge_radius_px == 2.0


def test_a_rule_cutting_as_alg1_keeps_its_fault_free_row_when_alg1_ran_under_a_crash(
        tmp_path, monkeypatch):
    """paper-labels cuts as Alg. 1 on a fault-free network; under a crash the run's Alg. 1 row
    holds the links cut robot-lost, which paper-labels, run fault-free, never cuts."""
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path / "cache"))
    clean, _ = _run(tmp_path, "clean")
    crashed, rows = _run(tmp_path, "crashed", FaultConfig(crash=((0, 0),)))
    assert any(r["reason"] == "robot-lost" for r in rows)
    q = crashed["resolution_quality"]
    assert q["paper"] != clean["resolution_quality"]["paper"]  # the crash shows in the run's row
    assert q["paper-labels"] == clean["resolution_quality"]["paper-labels"]
