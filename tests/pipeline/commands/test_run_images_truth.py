"""run-images --truth homographies on the downscaled Graffiti: the truth column and the
ground-truth figures of the report agree with each other and with the truth recomputed here
from the data set's homographies and the keypoints of ``sparse/``."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

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
    return report, rows, out


def _mapped(H, pts):
    x = np.c_[pts, np.ones(len(pts))] @ H.T
    return x[:, :2] / x[:, 2:]


def truth_by_hand(out: Path, report: dict, tol_px: float = 2.0):
    """The truth of the run recomputed from its ``sparse/`` keypoints (COLMAP's pixel
    convention, every keypoint of each image) and ``H1to{k}p.txt``: a link is good when each
    end maps within ``tol_px`` of the other; the true pairs of two images are the mutual
    nearest neighbours after the mapping, within ``tol_px`` both ways (by full distance
    matrices). Returns ``(good(links), true pairs as {(global a, global b)}, offsets)``."""
    import pycolmap
    from PIL import Image

    rec = pycolmap.Reconstruction(str(out / "sparse"))
    by_name = {im.name: im for im in rec.images.values()}
    names = [im["name"] for im in report["images"]]
    for im in report["images"]:  # processed at the files' size: one pixel grid
        with Image.open(GRAF_SMALL / im["name"]) as f:
            assert list(f.size) == im["size"]
    kp = [np.array([p.xy for p in by_name[n].points2D]) - 0.5 for n in names]
    assert [len(k) for k in kp] == report["features_per_camera"]
    H1 = [np.eye(3)] + [np.loadtxt(GRAF_SMALL / f"H1to{k}p.txt") for k in range(2, len(names) + 1)]
    # H1to{k}p belongs to the k-th file name; camera order is by content
    H1 = [H1[k] for k in np.argsort(np.argsort(names))]
    off = np.concatenate([[0], np.cumsum([len(k) for k in kp])])
    true = set()
    for i in range(len(kp)):
        for j in range(i + 1, len(kp)):
            d_ij = np.linalg.norm(_mapped(H1[j] @ np.linalg.inv(H1[i]), kp[i])[:, None]
                                  - kp[j][None], axis=2)                    # (m_i, m_j)
            d_ji = np.linalg.norm(kp[i][:, None]
                                  - _mapped(H1[i] @ np.linalg.inv(H1[j]), kp[j])[None], axis=2)
            s, r = d_ij.argmin(axis=1), d_ji.argmin(axis=0)
            for a in np.flatnonzero(r[s] == np.arange(len(s))).tolist():
                if d_ij[a, s[a]] <= tol_px and d_ji[a, s[a]] <= tol_px:
                    true.add((int(off[i] + a), int(off[j] + s[a])))
    return kp, H1, true, off


def test_every_ground_truth_figure_matches_the_truth_recomputed_here(graffiti_run):
    report, rows, out = graffiti_run
    kp, H1, true, off = truth_by_hand(out, report)
    link = np.array([[int(r[k]) for k in ("cam_i", "feat_i", "cam_j", "feat_j")] for r in rows])
    ci, fi, cj, fj = link.T
    # the truth column: each end maps within 2 px of the other
    good = [np.linalg.norm(_mapped(H1[j] @ np.linalg.inv(H1[i]), kp[i][[r]]) - kp[j][s]) <= 2
            and np.linalg.norm(_mapped(H1[i] @ np.linalg.inv(H1[j]), kp[j][[s]]) - kp[i][r]) <= 2
            for i, r, j, s in link.tolist()]
    assert [r["truth"] for r in rows] == ["1" if g else "0" for g in good]
    # true pairs, missing links (true pairs on comm edges that are not links)
    assert report["ground_truth"]["true_pairs"] == len(true) > 1000
    edges = {tuple(e) for e in report["comm_edges"]}
    cam = np.repeat(np.arange(len(kp)), np.diff(off))
    on_edges = {(a, b) for a, b in true if (cam[a], cam[b]) in edges}
    a, b = off[ci] + fi, off[cj] + fj
    kept = np.array([r["status"] == "kept" for r in rows])
    cut_by_resolution = np.array([r["reason"] == "resolution" for r in rows])
    for stage, alive in (("before", np.ones(len(rows), bool)), ("after", kept)):
        linked = set(zip(a[alive].tolist(), b[alive].tolist(), strict=True))
        assert report[stage]["missing_links"] == len(on_edges - linked), stage
    assert report["before"]["missing_links"] > 0
    # pairwise scores of the pairs implied by the closure of the links
    m = int(off[-1])
    for stage, alive in (("before", np.ones(len(rows), bool)),
                         ("after_resolution", ~cut_by_resolution), ("after", kept)):
        graph = coo_matrix((np.ones(alive.sum()), (a[alive], b[alive])), shape=(m, m))
        _, label = connected_components(graph, directed=False)
        size = np.bincount(label)
        predicted = int((size * (size - 1) // 2).sum())
        correct = sum(label[x] == label[y] for x, y in true)
        got = report["pairwise"][stage]
        assert (got["predicted_pairs"], got["correct_pairs"], got["true_pairs"]) == \
            (predicted, correct, len(true)), stage
        precision, recall = correct / predicted, correct / len(true)
        assert got["f1"] == pytest.approx(2 * precision * recall / (precision + recall))


def test_truth_column_filled_and_counted(graffiti_run):
    report, rows, _ = graffiti_run
    assert rows and all(r["truth"] in ("0", "1") for r in rows)
    good = sum(r["truth"] == "1" for r in rows)
    assert report["before"]["good_links"] == good
    assert report["before"]["spurious_links"] == len(rows) - good
    kept_good = sum(r["truth"] == "1" and r["status"] == "kept" for r in rows)
    assert report["after"]["good_links"] == kept_good
    # SIFT on a textured wall: most matches of neighbouring views are true
    assert good / len(rows) > 0.5


def test_pairwise_and_baselines_present(graffiti_run):
    report, _, _ = graffiti_run
    for bl in report["baselines"].values():
        assert {"good_links", "spurious_links", "missing_links", "pairwise"} <= set(bl)
    assert report["ground_truth"]["tolerance_px"] == 2.0
    assert report["ground_truth"]["doubt"] is None  # the right homographies raise no doubt
    assert report["resolution"]["good_deleted"] + report["resolution"]["spurious_deleted"] == \
        report["resolution"]["deleted_links"]


def test_missing_homographies_is_an_input_error(tmp_path, capsys):
    for name in ("img1.png", "img2.png"):
        (tmp_path / name).write_bytes((GRAF_SMALL / name).read_bytes())
    code = main(["run-images", str(tmp_path), "--graph", "ring", "--truth", "homographies",
                 "--no-rerun", "--no-fusion", "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err
    assert "H1to2p.txt" in err
    assert "[features]" not in err  # refused at load, before any work


def test_homographies_of_another_size_are_doubted(tmp_path, capsys):
    """Homographies of the images at twice their size (those of the originals given with
    resized copies): no link agrees, and the run says so rather than reporting 0 good links
    silently."""
    import numpy as np

    S = np.diag([2.0, 2.0, 1.0])
    for k in (1, 2, 3):
        (tmp_path / f"img{k}.png").write_bytes((GRAF_SMALL / f"img{k}.png").read_bytes())
        if k > 1:
            H = S @ np.loadtxt(GRAF_SMALL / f"H1to{k}p.txt") @ np.linalg.inv(S)
            np.savetxt(tmp_path / f"H1to{k}p.txt", H / H[2, 2])
    out = tmp_path / "o"
    assert main(["run-images", str(tmp_path), "--graph", "complete", "--truth",
                 "homographies", "--no-rerun", "--no-fusion", "--out", str(out)]) == 0
    truth = json.loads((out / "report.json").read_text())["ground_truth"]
    assert truth["doubt"] and "for these images at this size" in truth["doubt"]
    assert "agree with the homographies" in capsys.readouterr().err


def test_truth_doubt_needs_links_and_a_tiny_agreement():
    import numpy as np

    from pipeline.evaluation.truth import truth_doubt

    assert truth_doubt(np.zeros(19, bool), 2.0) is None          # too few links to judge
    assert truth_doubt(np.r_[np.ones(1, bool), np.zeros(19, bool)], 2.0) is None  # 5 %
    assert "0 of 20 links" in truth_doubt(np.zeros(20, bool), 2.0)
    # a folder without the reference image: the message says which image is image 1
    said = truth_doubt(np.zeros(20, bool), 2.0, ["img3.png", "img2.png", "img4.png"])
    assert "image 1 is img2.png, image 2 img3.png" in said


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


def test_conflictive_sets_well_and_wrongly_solved_are_counted_as_on_a_formation(graffiti_run):
    """Table IV's well / wrongly solved sets, a ground-truth figure of a formation run, were
    missing from a photo run with --truth: counted here from links.csv, a set wrongly solved
    when a link of it that the consistency stage kept is spurious."""
    report, rows, _ = graffiti_run
    m = report["features_per_camera"]
    off = np.concatenate([[0], np.cumsum(m)])
    a = np.array([off[int(r["cam_i"])] + int(r["feat_i"]) for r in rows])
    b = np.array([off[int(r["cam_j"])] + int(r["feat_j"]) for r in rows])
    _, comp = connected_components(coo_matrix((np.ones(len(a)), (a, b)),
                                              shape=(off[-1], off[-1])), directed=False)
    cam = np.repeat(np.arange(len(m)), m)
    members = {}
    for f in np.unique(np.r_[a, b]):
        members.setdefault(comp[f], []).append(cam[f])
    conflictive = {c for c, cams in members.items() if len(cams) > len(set(cams))}
    wrong = {comp[x] for x, r in zip(a, rows, strict=True) if comp[x] in conflictive
             and r["reason"] not in ("resolution", "robot-lost") and r["truth"] == "0"}
    res = report["resolution"]
    assert report["before"]["conflictive_sets"] == len(conflictive) > 0
    assert (res["sets_well_solved"], res["sets_wrongly_solved"]) == (
        len(conflictive) - len(wrong), len(wrong))
