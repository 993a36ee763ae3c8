"""run-images --truth homographies on the downscaled Graffiti: the truth column and the
ground-truth figures of the report agree with each other."""

import csv
import json
from pathlib import Path

import pytest

from pipeline.__main__ import main

GRAF_SMALL = Path(__file__).resolve().parents[2] / "data" / "graffiti_small"


@pytest.fixture(scope="module")
def graffiti_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "graffiti-ring2"
    assert main(["run-images", str(GRAF_SMALL), "--graph", "ring2", "--truth", "homographies",
                 "--no-rerun", "--no-fusion", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return report, rows


def test_truth_column_filled_and_counted(graffiti_run):
    report, rows = graffiti_run
    assert rows and all(r["truth"] in ("0", "1") for r in rows)
    good = sum(r["truth"] == "1" for r in rows)
    assert report["before"]["good_links"] == good
    assert report["before"]["spurious_links"] == len(rows) - good
    kept_good = sum(r["truth"] == "1" and r["status"] == "kept" for r in rows)
    assert report["after"]["good_links"] == kept_good
    # SIFT on a textured wall: most matches of neighbouring views are true
    assert good / len(rows) > 0.5
    assert report["before"]["missing_links"] >= 0


def test_pairwise_and_baselines_present(graffiti_run):
    report, _ = graffiti_run
    for k in ("before", "after_resolution", "after"):
        assert 0 < report["pairwise"][k]["f1"] <= 1
    for bl in report["baselines"].values():
        assert {"good_links", "spurious_links", "missing_links", "pairwise"} <= set(bl)
    assert report["ground_truth"]["tolerance_px"] == 2.0
    assert report["resolution"]["good_deleted"] + report["resolution"]["spurious_deleted"] == \
        report["resolution"]["deleted_links"]


def test_missing_homographies_is_an_input_error(tmp_path, capsys):
    for name in ("img1.png", "img2.png"):
        (tmp_path / name).write_bytes((GRAF_SMALL / name).read_bytes())
    code = main(["run-images", str(tmp_path), "--graph", "ring", "--truth", "homographies",
                 "--no-rerun", "--no-fusion", "--out", str(tmp_path / "o")])
    assert code == 2
    assert "H1to2p.txt" in capsys.readouterr().err
