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


def _graffiti_at_full_scale(folder: Path) -> Path:
    """The downscaled Graffiti brought back to the data set's 800x640 (bicubic), its
    homographies conjugated by the same scaling (OpenCV pixel centres, as its SOURCE.txt)."""
    import cv2
    import numpy as np

    folder.mkdir(parents=True, exist_ok=True)
    s = 2.0
    S = np.array([[s, 0, s / 2 - 0.5], [0, s, s / 2 - 0.5], [0, 0, 1]])
    for k in range(1, 7):
        img = cv2.imread(str(GRAF_SMALL / f"img{k}.png"))
        cv2.imwrite(str(folder / f"img{k}.png"),
                    cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC))
        if k > 1:
            H = S @ np.loadtxt(GRAF_SMALL / f"H1to{k}p.txt") @ np.linalg.inv(S)
            np.savetxt(folder / f"H1to{k}p.txt", H / H[2, 2])
    return folder


def test_fusion_on_graffiti_cuts_more_spurious_than_good_links(tmp_path):
    """The fusion gates follow each robot's measured keypoint noise (pipeline.fusion.noise).

    At the data set's own scale the keypoint errors of the strongest viewpoint changes reach
    a few pixels; a fixed 1 px noise model cut more good links than spurious ones there
    (this copy, complete graph: 52 good / 40 spurious; the 800x640 originals: 67 / 62). At
    400 px the errors are half as large in pixels, so the fixed model passed by chance: the
    guard runs on the copy brought back to 800x640."""
    folder = _graffiti_at_full_scale(tmp_path / "graffiti")
    out = tmp_path / "run"
    assert main(["run-images", str(folder), "--graph", "complete", "--truth", "homographies",
                 "--no-rerun", "--out", str(out)]) == 0
    fusion = json.loads((out / "report.json").read_text())["fusion"]
    assert fusion["noise"] == "measured"
    # the robots of the strong viewpoint changes measure more than the 1 px floor
    assert max(fusion["robot_sigma_px"]) > 1.2 and min(fusion["robot_sigma_px"]) >= 1.0
    assert fusion["cut_spurious"] > fusion["cut_good"] or fusion["cut_links"] == 0
