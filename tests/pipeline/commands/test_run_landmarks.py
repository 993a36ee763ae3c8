"""run-landmarks on six CMU hotel frames: the report contract, scores that agree with
links.csv, and clear errors."""

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.consistency.rules import RULES as RESOLUTIONS
from pipeline.evaluation.metrics import association_pairs, pairwise_scores
from pipeline.runs.landmarks import true_landmark_pairs
from pipeline.types import Links

HOTEL = Path(__file__).resolve().parents[2] / "data" / "cmu_hotel_small"


@pytest.fixture(scope="module", params=[("complete", "votes", "none"), ("ring", "none", "0.8")])
def hotel_run(request, tmp_path_factory):
    graph, refine, ratio = request.param
    out = tmp_path_factory.mktemp("runs") / f"hotel-{graph}"
    assert main(["run-landmarks", str(HOTEL), "--graph", graph, "--refine", refine, "--ratio",
                 ratio, "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return report, rows


def test_report_contract(hotel_run):
    report, rows = hotel_run
    for side in ("before", "after"):
        assert set(report["pairwise"][side]) >= {"precision", "recall", "f1"}
    assert report["cycle_consistent"] is True
    assert report["after"]["conflictive_sets"] == 0
    assert report["features_per_camera"] == [30] * 6
    assert set(report["baselines"]) == {"drop_conflictive_sets", "keep_first_per_image",
                                        "quality_merge", "spectral_sync", "clear"}
    r = report["resolution"]
    assert r["method"] == "sync" and r["messages"] > 0 and r["bytes"] > 0  # links only
    assert len(rows) == report["before"]["links"]
    assert report["matching"]["geometry"] == "epipolar"  # the default
    assert report["matching"]["edges"] == len(report["comm_edges"])
    ref = report["refinement"]
    assert ref["method"] in ("votes", "none")
    if ref["method"] == "votes":
        assert ref["rounds"] == 2 * ref["iterations"] and ref["bytes"] > 0
    else:
        assert report["pairwise"]["input_links"] == report["pairwise"]["before_links"]


def test_scores_recomputed_from_links_csv(hotel_run):
    report, rows = hotel_run
    kept = [r for r in rows if r["status"] == "kept"]
    links = Links(*[np.array([int(r[k]) for r in kept]) for k in ("cam_i", "feat_i", "cam_j", "feat_j")])
    m = report["features_per_camera"]
    s = pairwise_scores(association_pairs(m, links), true_landmark_pairs(m), sum(m))
    assert s["f1"] == pytest.approx(report["pairwise"]["after"]["f1"])
    # truth column: the two ends carry the same label row
    assert all(r["truth"] == str(int(r["feat_i"] == r["feat_j"])) for r in rows)
    assert report["after"]["good_links"] == sum(r["truth"] == "1" for r in kept)


@pytest.mark.parametrize("rule, refine", [("sync", "none"), ("evidence", "none"),
                                          ("paper-labels", "votes")])
def test_refinement_follows_the_rule(tmp_path, rule, refine):
    """Without --refine: the votes only for a rule that does not weigh the links' cycles."""
    from pipeline.consistency.rules import get_rule
    from pipeline.runs.landmarks import default_refinement

    assert default_refinement(rule) == refine
    assert get_rule(rule).weighs_cycles == (refine == "none")
    out = tmp_path / rule
    assert main(["run-landmarks", str(HOTEL), "--graph", "ring", "--resolution", rule,
                 "--no-baselines", "--out", str(out), "-q"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["refinement"]["method"] == refine and report["config"]["refine"] == refine


def test_true_pairs_count():
    assert len(true_landmark_pairs([3, 3, 3])) == 9


def test_only_existing_resolution_methods_are_offered(tmp_path, capsys):
    assert "paper" in RESOLUTIONS
    with pytest.raises(SystemExit):
        main(["run-landmarks", str(HOTEL), "--resolution", "nope", "--out", str(tmp_path / "o")])
    assert "invalid choice" in capsys.readouterr().err


def test_bad_inputs_fail_cleanly(tmp_path, capsys):
    assert main(["run-landmarks", str(tmp_path / "none"), "--out", str(tmp_path / "o")]) == 2
    assert "no such folder" in capsys.readouterr().err
    assert main(["run-landmarks", str(HOTEL), "--frames", "9", "--out", str(tmp_path / "o")]) == 2
    assert "--frames 9" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["run-landmarks", str(HOTEL), "--ratio", "2"])
    assert not (tmp_path / "o").exists()


def test_out_holding_the_input_folder_is_refused(tmp_path, capsys):
    data = tmp_path / "hotel"
    shutil.copytree(HOTEL, data)
    before = sorted(p.name for p in data.iterdir())
    assert main(["run-landmarks", str(data), "--out", str(tmp_path)]) == 2
    assert "holds the input DIR" in capsys.readouterr().err
    assert sorted(p.name for p in data.iterdir()) == before


def test_true_pairs_of_partly_seen_landmarks():
    # image 0 sees landmarks 0, 2; image 1 sees 0, 1, 2; image 2 sees 1
    pairs = true_landmark_pairs([2, 3, 1], [np.array([0, 2]), np.array([0, 1, 2]), np.array([1])])
    assert sorted(map(tuple, pairs.tolist())) == [(0, 2), (1, 4), (3, 5)]


def test_landmarks_not_seen_by_every_image(tmp_path):
    """Hotel frames where each image hides a few landmarks (``nan nan`` rows): the features
    follow what each image sees, and the truth column and the scores agree with the label
    rows of ``feature_landmarks``."""
    data = tmp_path / "hotel"
    shutil.copytree(HOTEL, data)
    rng = np.random.default_rng(3)
    for k, p in enumerate(sorted(data.glob("hotel*.txt"))):
        rows = np.loadtxt(p)
        rows[rng.choice(30, 3 + k % 3, replace=False)] = np.nan
        np.savetxt(p, rows)
    out = tmp_path / "run"
    assert main(["run-landmarks", str(data), "--graph", "complete", "--out", str(out), "-q",
                 "--no-baselines"]) == 0
    report = json.loads((out / "report.json").read_text())
    lm = [np.asarray(x) for x in report["feature_landmarks"]]
    m = report["features_per_camera"]
    assert m == [len(x) for x in lm] and m != [30] * 6 and all(len(x) < 30 for x in lm)
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    same = [lm[int(r["cam_i"])][int(r["feat_i"])] == lm[int(r["cam_j"])][int(r["feat_j"])]
            for r in rows]
    assert [r["truth"] == "1" for r in rows] == same
    kept = [r for r in rows if r["status"] == "kept"]
    links = Links(*[np.array([int(r[k]) for r in kept]) for k in ("cam_i", "feat_i", "cam_j", "feat_j")])
    s = pairwise_scores(association_pairs(m, links), true_landmark_pairs(m, lm), sum(m))
    assert s["f1"] == pytest.approx(report["pairwise"]["after"]["f1"])
    assert report["cycle_consistent"] is True


def test_a_graph_that_splits_the_images_is_warned(tmp_path, capsys):
    """A graph file of two separate groups: said, as run-images says it."""
    graph = tmp_path / "g.csv"
    graph.write_text("0,1\n1,2\n3,4\n4,5\n")
    assert main(["run-landmarks", str(HOTEL), "--graph", str(graph), "--out",
                 str(tmp_path / "r")]) == 0
    assert "splits the 6 images into 2 groups" in capsys.readouterr().err


def test_a_run_without_links_is_warned_in_report_and_on_stderr(tmp_path, capsys):
    """A --ratio gate that keeps no match leaves nothing to associate: the run says so, as
    every other command does, instead of a table of zero scores."""
    out = tmp_path / "r"
    assert main(["run-landmarks", str(HOTEL), "--graph", "line", "--descriptors", "sift",
                 "--ratio", "0.0001", "--no-baselines", "--out", str(out), "-q"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["before"]["links"] == 0
    assert [w["code"] for w in report["warnings"]] == ["no-links"]
    err = capsys.readouterr().err
    assert "warning: the input holds no link between two images" in err and "--ratio" in err


def test_a_clean_run_carries_no_warnings(hotel_run):
    report, _ = hotel_run
    assert "warnings" not in report and "conflict_free" not in report
