"""clean-db: round trip on databases built by the tests, input never modified, bad input."""

import hashlib
import json

import numpy as np
import pytest

from pipeline import colmap
from pipeline.__main__ import main
from pipeline.association import AssociationGraph, count_conflicts
from pipeline.types import Features, Links, View


def _db_with_planted_conflicts(path, n=4, m=30):
    """Four images; chains of clean links plus two planted cycles that close on a second feature
    of the same image (the paper's Fig. 1 pattern): two conflictive sets."""
    rng = np.random.default_rng(0)
    views, feats = [], []
    for k in range(n):
        K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
        views.append(View(f"view_{k}.jpg", np.zeros((240, 320, 3), np.uint8), K))
        kp = rng.uniform([0, 0], [319, 239], size=(m, 2)).astype(np.float32)
        feats.append(Features(kp, np.zeros((m, 128), np.float32), np.ones(m, np.float32), "sift"))
    rows = []
    for r in range(10, 20):  # clean tracks: feature r in every image, along the ring
        rows += [(0, r, 1, r), (1, r, 2, r), (2, r, 3, r)]
    rows += [(0, 0, 1, 0), (1, 0, 2, 0), (0, 1, 2, 0)]          # 0:0 - 1:0 - 2:0 - 0:1
    rows += [(1, 5, 2, 5), (2, 5, 3, 5), (1, 6, 3, 5)]          # 1:5 - 2:5 - 3:5 - 1:6
    ci, fi, cj, fj = np.array(rows).T
    links = Links(ci, fi, cj, fj)
    colmap.write_database(path, views, feats, links)
    return views, feats, links


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_round_trip_cuts_the_conflicts_and_nothing_else(tmp_path, capsys):
    src = tmp_path / "in.db"
    _, feats, links = _db_with_planted_conflicts(src)
    digest = _sha(src)
    m = [len(f) for f in feats]
    assert count_conflicts(AssociationGraph(m, links)).conflictive_sets == 2

    out = tmp_path / "out" / "clean.db"
    report = tmp_path / "clean.json"
    assert main(["clean-db", str(src), "--out", str(out), "--report", str(report)]) == 0
    printed = capsys.readouterr().out
    assert "conflictive sets: 2 before, 0 after" in printed

    assert _sha(src) == digest  # the input is never modified
    cleaned = colmap.read_database(out)
    assert count_conflicts(AssociationGraph(m, cleaned.links)).conflictive_sets == 0
    kept = {tuple(r) for r in np.stack([cleaned.links.cam_i, cleaned.links.feat_i,
                                        cleaned.links.cam_j, cleaned.links.feat_j], 1).tolist()}
    given = {tuple(r) for r in np.stack([links.cam_i, links.feat_i, links.cam_j,
                                         links.feat_j], 1).tolist()}
    assert kept < given
    summary = json.loads(report.read_text())
    cut = given - kept
    assert summary["cut"]["resolution"] == len(cut) >= 2
    # every clean track survives: only links of the two planted cycles were cut
    assert all(r[1] < 10 for r in cut)
    assert summary["after"]["conflictive_sets"] == 0 and summary["before"]["conflictive_sets"] == 2


def test_baselines_beside_the_rule(tmp_path, capsys):
    """--baselines: every centralized baseline on the same verified links, in the summary and
    printed; what each deleted is its own mask's count."""
    from pipeline.consistency.centralized import BASELINES

    src, out, report = tmp_path / "in.db", tmp_path / "out.db", tmp_path / "s.json"
    _, feats, links = _db_with_planted_conflicts(src)
    assert main(["clean-db", str(src), "--out", str(out), "--report", str(report),
                 "--baselines", "--no-rerun"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads(report.read_text())
    m = np.array([len(f.keypoints) for f in feats], dtype=np.int64)
    assert sorted(summary["baselines"]) == sorted(BASELINES)
    for name, fn in BASELINES.items():
        mask = np.asarray(fn(m, links), dtype=bool)
        assert summary["baselines"][name]["deleted_links"] == int((~mask).sum()), name
        assert f"baseline {name}: " in printed
    # the two planted conflictive sets are left by none of the baselines that drop or merge
    assert summary["baselines"]["drop_conflictive_sets"]["conflictive_sets"] == 0


def test_comm_graph_file_cuts_links_between_non_neighbours(tmp_path):
    src = tmp_path / "in.db"
    _, feats, links = _db_with_planted_conflicts(src)
    graph = tmp_path / "path.csv"
    graph.write_text("view_0.jpg,view_1.jpg\nview_1.jpg,view_2.jpg\n2,3\n")  # no 0-2, no 1-3
    out = tmp_path / "clean.db"
    report = tmp_path / "r.json"
    assert main(["clean-db", str(src), "--out", str(out), "--comm-graph", str(graph),
                 "--report", str(report)]) == 0
    summary = json.loads(report.read_text())
    assert summary["cut"]["not-comm-edge"] == 2  # (0,1)-(2,0) and (1,6)-(3,5)
    cleaned = colmap.read_database(out)
    pairs = set(zip(cleaned.links.cam_i.tolist(), cleaned.links.cam_j.tolist(), strict=True))
    assert pairs <= {(0, 1), (1, 2), (2, 3)}
    # without the chords the planted cycles are open chains: nothing left to resolve
    assert summary["before"]["conflictive_sets"] == 0 and summary["cut"]["resolution"] == 0


def test_sceaux_database_round_trip(tmp_path, sceaux_small):
    """A database built with pycolmap from real matches (all pairs of 4 Sceaux images)."""
    from pipeline.commgraph import comm_graph
    from pipeline.inputs.photos import load_folder
    from pipeline.matching.features import extract_all
    from pipeline.matching.pairs import match_edges

    views = load_folder(sceaux_small, max_size=640)
    feats = extract_all(views, "sift", 1500)
    links = Links.from_matches(match_edges(feats, views, comm_graph("complete", [v.name for v in views])))
    src = colmap.write_database(tmp_path / "sceaux.db", views, feats, links)
    out = tmp_path / "sceaux-clean.db"
    assert main(["clean-db", str(src), "--out", str(out)]) == 0
    cleaned = colmap.read_database(out)
    m = [len(f) for f in feats]
    assert count_conflicts(AssociationGraph(m, cleaned.links)).conflictive_sets == 0
    assert 0 < len(cleaned.links) <= len(links)
    result = colmap.incremental_mapping(out)  # COLMAP's mapper runs on the cleaned database
    assert result.registered_images >= 3


def test_database_made_by_colmap_itself(tmp_path, sceaux_small):
    """COLMAP's own SIFT extraction and exhaustive matcher (6-column keypoints, rigs, frames):
    clean-db removes its conflicts and COLMAP's mapper still runs on the result."""
    import pycolmap

    src = tmp_path / "colmap.db"
    options = pycolmap.FeatureExtractionOptions()
    options.sift.max_num_features = 1000
    options.num_threads = 2
    with colmap.quiet_colmap():
        pycolmap.extract_features(src, sceaux_small, extraction_options=options)
        pycolmap.match_exhaustive(src)
    digest = _sha(src)
    before = colmap.read_database(src)
    m = before.features_per_camera
    n_conflicts = count_conflicts(AssociationGraph(m, before.links.subset(~before.not_one_to_one)))
    out = tmp_path / "colmap-clean.db"
    report = tmp_path / "r.json"
    assert main(["clean-db", str(src), "--out", str(out), "--report", str(report)]) == 0
    assert _sha(src) == digest
    summary = json.loads(report.read_text())
    assert summary["before"]["conflictive_sets"] == n_conflicts.conflictive_sets
    cleaned = colmap.read_database(out)
    assert count_conflicts(AssociationGraph(m, cleaned.links)).conflictive_sets == 0
    assert len(cleaned.links) == len(before.links) - sum(summary["cut"].values())
    assert colmap.incremental_mapping(out).registered_images >= 3


# ------------------------------------------------------------------------------------ bad input

def _fails(argv, capsys, match):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err, err


def test_database_without_two_view_geometries(tmp_path, capsys):
    src = tmp_path / "raw.db"
    views = [View(f"v{k}.jpg", np.zeros((10, 10), np.uint8), np.eye(3)) for k in range(2)]
    feats = [Features(np.zeros((3, 2), np.float32), np.zeros((3, 128), np.float32),
                      np.ones(3, np.float32), "sift") for _ in range(2)]
    colmap.write_database(src, views, feats, Links([], [], [], []))
    out = tmp_path / "out.db"
    _fails(["clean-db", str(src), "--out", str(out)], capsys, "no two-view geometries")
    assert not out.exists()


def test_missing_database(tmp_path, capsys):
    _fails(["clean-db", str(tmp_path / "nope.db"), "--out", str(tmp_path / "o.db")], capsys,
           "no such file")


def test_output_equal_to_input(tmp_path, capsys):
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    digest = _sha(src)
    _fails(["clean-db", str(src), "--out", str(src)], capsys, "never modified")
    assert _sha(src) == digest


def test_comm_graph_naming_an_unknown_image(tmp_path, capsys):
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    graph = tmp_path / "g.csv"
    graph.write_text("view_0.jpg,view_1.jpg\nview_1.jpg,castle.jpg\n")
    out = tmp_path / "o.db"
    _fails(["clean-db", str(src), "--out", str(out), "--comm-graph", str(graph)], capsys,
           "line 2: image 'castle.jpg' is not one of the")
    assert not out.exists()


def test_not_a_database(tmp_path, capsys):
    src = tmp_path / "notes.db"
    src.write_text("not sqlite")
    _fails(["clean-db", str(src), "--out", str(tmp_path / "o.db")], capsys, "not an SQLite file")


def test_out_is_required(tmp_path):
    with pytest.raises(SystemExit):
        main(["clean-db", str(tmp_path / "in.db")])


def test_writes_links_csv_and_recording_beside_the_database(tmp_path, capsys):
    from pipeline.inputs.linkscsv import read_run_links_csv
    from viz.recording_reader import entity_paths

    src = tmp_path / "in.db"
    _, _, links = _db_with_planted_conflicts(src)
    out = tmp_path / "clean.db"
    assert main(["clean-db", str(src), "--out", str(out)]) == 0
    assert "clean.links.csv" in capsys.readouterr().out
    side = read_run_links_csv(tmp_path / "clean.links.csv")
    assert len(side.links) == len(links)
    deleted = side.status == "deleted"
    assert deleted.sum() == 2 and set(side.reason[deleted]) == {"resolution"}
    assert (side.round[deleted] >= 1).all()
    cleaned = colmap.read_database(out)
    assert len(cleaned.links) == len(links) - deleted.sum()
    paths = entity_paths(tmp_path / "clean.rrd")
    assert any("keypoints" in p for p in paths)
    # resolve reads the side file back: nothing left to cut
    assert main(["resolve", "--links", str(tmp_path / "clean.links.csv"),
                 "--out", str(tmp_path / "again.csv")]) == 0
    assert "deleted: 0 links" in capsys.readouterr().out


def _db_with_a_twin_pair(path, n=5, points=60, twin_points=25):
    """Five calibrated cameras on an arc round a point cloud, every pair matched on the true
    projections, except pair (0, 3): its matches are what a twin of the scene would give (image
    3's side seen from a pose turned 45° about the vertical axis), a valid but wrong two-view
    geometry, with fewer inliers than the right pairs (as the wrong pairs of the rendered ring
    have: 15-30 against 100-500). Each pair's points are its own, so no set holds two
    features of one image."""
    from data_synth.formations import look_at

    rng = np.random.default_rng(1)
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    poses = [look_at([8 * np.sin(a), -8 * np.cos(a), 1.0], [0, 0, 0])
             for a in np.deg2rad(np.linspace(-40, 40, n))]
    a = np.deg2rad(45)
    twin = (poses[3][0] @ np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0],
                                    [0, 0, 1]]), poses[3][1])

    def project(pose, X):
        x = (K @ (pose[0] @ X.T + pose[1][:, None])).T
        return (x[:, :2] / x[:, 2:]).astype(np.float32)

    kps = [[] for _ in range(n)]
    rows, twin_rows = [], []
    for i in range(n):
        for j in range(i + 1, n):
            X = rng.uniform(-1.5, 1.5, size=(twin_points if (i, j) == (0, 3) else points, 3))
            pj = twin if (i, j) == (0, 3) else poses[j]
            fi, fj = sum(len(k) for k in kps[i]), sum(len(k) for k in kps[j])
            kps[i].append(project(poses[i], X))
            kps[j].append(project(pj, X))
            got = [(i, fi + p, j, fj + p) for p in range(len(X))]
            (twin_rows if (i, j) == (0, 3) else rows).extend(got)
    views = [View(f"view_{k}.jpg", np.zeros((240, 320, 3), np.uint8), K) for k in range(n)]
    feats = [Features(np.concatenate(k), np.zeros((sum(map(len, k)), 128), np.float32),
                      np.ones(sum(map(len, k)), np.float32), "sift") for k in kps]
    ci, fi, cj, fj = np.array(rows + twin_rows).T
    colmap.write_database(path, views, feats, Links(ci, fi, cj, fj))
    return len(twin_rows)


def test_loop_check_drops_the_twin_pair(tmp_path, capsys):
    """--loop-check: the pair whose rotation breaks its triangles loses all its links (reason
    loop-inconsistent), every other pair keeps all of its; without it nothing is cut."""
    src = tmp_path / "twin.db"
    n_twin = _db_with_a_twin_pair(src)
    out, report = tmp_path / "loop.db", tmp_path / "loop.json"
    assert main(["clean-db", str(src), "--out", str(out), "--report", str(report),
                 "--loop-check", "--no-rerun"]) == 0
    assert "loop check: 1 of 10 image pairs break their rotation loops" in capsys.readouterr().out
    summary = json.loads(report.read_text())
    assert summary["cut"]["loop-inconsistent"] == n_twin
    assert summary["loop_check"]["pairs_dropped"] == 1
    cleaned = colmap.read_database(out)
    pairs = set(zip(cleaned.links.cam_i.tolist(), cleaned.links.cam_j.tolist(), strict=True))
    assert pairs == {(i, j) for i in range(5) for j in range(i + 1, 5)} - {(0, 3)}
    assert len(cleaned.links) == len(colmap.read_database(src).links) - n_twin

    plain = tmp_path / "plain.json"
    assert main(["clean-db", str(src), "--out", str(tmp_path / "plain.db"), "--report",
                 str(plain), "--no-rerun"]) == 0
    summary = json.loads(plain.read_text())
    assert "loop-inconsistent" not in summary["cut"] and "loop_check" not in summary
    assert sum(summary["cut"].values()) == 0


@pytest.mark.parametrize("argv, message", [
    (["--loop-tol", "10"], "without --loop-check"),
    (["--loop-check", "--loop-tol", "0"], "between 0 and 180"),
    (["--loop-check", "--loop-tol", "180"], "between 0 and 180"),
    (["--loop-check", "--loop-tol", "nan"], "between 0 and 180"),
    (["--loop-check", "--loop-tol", "ten"], "--loop-tol 'ten'"),
])
def test_bad_loop_options_are_named(tmp_path, capsys, argv, message):
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    out = tmp_path / "o.db"
    assert main(["clean-db", str(src), "--out", str(out), "--no-rerun", *argv]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def _db_with_a_wrong_consistent_track(path, n=8, points=250, planted=20, noise_px=0.3):
    """Eight calibrated cameras round a point cloud, every pair matched on the true
    projections (with ``noise_px`` of noise), plus ``planted`` wrong links that no consistency
    stage can see: point ``A_k``, seen by cameras 0-3 only, is linked in camera 3 to point
    ``B_k`` of camera 5, ``B_k`` seen by cameras 5 and 6 only. The set ``A_k ∪ B_k`` holds each
    camera once (conflict-free), but its observations are not one point. Returns the planted
    links as ``(cam_i, feat_i, cam_j, feat_j)`` tuples and the links of the full tracks."""
    from data_synth.formations import look_at

    rng = np.random.default_rng(3)
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    poses = [look_at([8 * np.cos(a), 8 * np.sin(a), 1.5], [0, 0, 0])
             for a in np.linspace(0, 2 * np.pi, n, endpoint=False)]
    X = rng.uniform(-1.5, 1.5, size=(points + 2 * planted, 3))
    seen = [list(range(points)) for _ in range(n)]
    A, B = np.arange(points, points + planted), np.arange(points + planted, points + 2 * planted)
    for c in range(4):
        seen[c] += A.tolist()
    for c in (5, 6):
        seen[c] += B.tolist()
    kps, feat_of = [], []
    for c, (R, t) in enumerate(poses):
        x = (K @ (R @ X[seen[c]].T + t[:, None])).T
        kps.append((x[:, :2] / x[:, 2:] + rng.normal(0, noise_px, (len(seen[c]), 2)))
                   .astype(np.float32))
        feat_of.append({p: f for f, p in enumerate(seen[c])})
    rows = []
    for i in range(n):
        for j in range(i + 1, n):
            rows += [(i, feat_of[i][p], j, feat_of[j][p]) for p in sorted(set(seen[i]) &
                                                                          set(seen[j]))]
    wrong = [(3, feat_of[3][a], 5, feat_of[5][b]) for a, b in zip(A, B, strict=True)]
    views = [View(f"view_{k}.jpg", np.zeros((240, 320, 3), np.uint8), K) for k in range(n)]
    feats = [Features(k, np.zeros((len(k), 128), np.float32), np.ones(len(k), np.float32),
                      "sift") for k in kps]
    ci, fi, cj, fj = np.array(rows + wrong).T
    colmap.write_database(path, views, feats, Links(ci, fi, cj, fj))
    full = {r for r in rows if r[1] < points and r[3] < points}
    return set(wrong), full


def _links_by_reason(csv_path) -> dict:
    import csv

    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    out: dict = {}
    for r in rows:
        key = (int(r["cam_i"]), int(r["feat_i"]), int(r["cam_j"]), int(r["feat_j"]))
        out.setdefault(r["reason"], set()).add(key)
    return out


def test_fusion_cuts_wrong_matches_the_consistency_stage_cannot_see(tmp_path, capsys):
    """--fusion: on the poses of a COLMAP mapping of the input, fusion votes the planted
    observations out of their conflict-free tracks and cuts every planted link (reason
    fusion-outlier, in the summary and in OUT.links.csv), and almost no link of the true
    tracks; without it the same database comes out uncut."""
    src = tmp_path / "wrong.db"
    wrong, full = _db_with_a_wrong_consistent_track(src)
    out, report = tmp_path / "fused.db", tmp_path / "fused.json"
    assert main(["clean-db", str(src), "--out", str(out), "--report", str(report), "--fusion",
                 "--no-rerun"]) == 0
    printed = capsys.readouterr().out
    assert "conflictive sets: 0 before, 0 after" in printed
    assert "of the input (8 of 8 images registered" in printed
    summary = json.loads(report.read_text())
    assert summary["fusion"]["enabled"] and summary["fusion"]["cameras"] == 8
    by_reason = _links_by_reason(tmp_path / "fused.links.csv")
    fused_out = by_reason.get("fusion-outlier", set())
    assert summary["cut"]["fusion-outlier"] == len(fused_out)
    assert wrong <= fused_out
    assert len(fused_out & full) <= 0.01 * len(full)
    cleaned = colmap.read_database(out)
    kept = set(zip(cleaned.links.cam_i.tolist(), cleaned.links.feat_i.tolist(),
                   cleaned.links.cam_j.tolist(), cleaned.links.feat_j.tolist(), strict=True))
    assert not kept & fused_out and len(kept) == len(colmap.read_database(src).links) - len(
        fused_out)

    plain = tmp_path / "plain.json"
    assert main(["clean-db", str(src), "--out", str(tmp_path / "plain.db"), "--report",
                 str(plain), "--no-rerun"]) == 0
    summary = json.loads(plain.read_text())
    assert "fusion" not in summary and sum(summary["cut"].values()) == 0


def test_fusion_without_poses_says_so_and_cuts_what_the_stage_cut(tmp_path, capsys):
    """--fusion on a database COLMAP cannot map (random keypoints): fusion does not run, the
    summary and the printout say why, and the cuts are the consistency stage's alone."""
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    report = tmp_path / "o.json"
    assert main(["clean-db", str(src), "--out", str(tmp_path / "o.db"), "--report",
                 str(report), "--fusion", "--no-rerun"]) == 0
    printed = capsys.readouterr().out
    assert "fusion: not run, camera poses unknown: the mapping registered 0 of 4 images" \
        in printed
    summary = json.loads(report.read_text())
    assert summary["fusion"]["enabled"] is False and summary["cut"]["fusion-outlier"] == 0
    assert summary["cut"]["resolution"] > 0 and summary["after"]["conflictive_sets"] == 0


def test_fusion_maps_only_the_links_on_the_comm_graph(tmp_path):
    """--fusion with --comm-graph: the links between non-neighbours are cut before the stage
    and left out of the mapping; fusion still cuts every planted link (pair (3, 5) is an
    edge) and the links it cuts are all on the graph."""
    src = tmp_path / "wrong.db"
    wrong, _ = _db_with_a_wrong_consistent_track(src)
    graph = tmp_path / "graph.txt"
    edges = [(k, (k + 1) % 8) for k in range(8)] + [(k, (k + 2) % 8) for k in range(8)]
    graph.write_text("".join(f"{i},{j}\n" for i, j in edges))
    report = tmp_path / "o.json"
    assert main(["clean-db", str(src), "--out", str(tmp_path / "o.db"), "--comm-graph",
                 str(graph), "--report", str(report), "--fusion", "--no-rerun"]) == 0
    summary = json.loads(report.read_text())
    assert summary["cut"]["not-comm-edge"] > 0 and summary["fusion"]["cameras"] == 8
    by_reason = _links_by_reason(tmp_path / "o.links.csv")
    assert wrong <= by_reason["fusion-outlier"]
    on_graph = {tuple(sorted(e)) for e in edges}
    assert all((r[0], r[2]) in on_graph for r in by_reason["fusion-outlier"])


def test_fusion_on_the_largest_of_several_models_says_so():
    """clean-db --fusion judges tracks on one COLMAP model: with several, the line says it is
    the largest and that the other models' images are not fused."""
    from pipeline.commands.clean_db import fusion_lines

    fu = {"enabled": True, "cameras": 4, "cameras_without_pose": ["g1", "g2", "g3"],
          "mapping": {"models": 2, "points": 1259, "mean_reprojection_error": 0.2}}
    lines = fusion_lines(fu, 0, 7)
    assert "4 of 7 images registered in the largest of its 2 models" in lines[0]
    assert "not fused (3 without a pose here" in lines[1] and len(lines) == 2
    one = fusion_lines({**fu, "mapping": {**fu["mapping"], "models": 1},
                        "cameras_without_pose": []}, 5, 4)
    assert "largest" not in one[0] and "5 links cut" in one[0] and len(one) == 2
    assert fusion_lines({"enabled": False, "reason": "camera poses unknown"}, 0, 4) == \
        ["fusion: not run, camera poses unknown"]


def test_no_rerun_beside_an_earlier_recording_warns_that_it_is_stale(tmp_path, capsys):
    """--overwrite --no-rerun replaced OUT.db and OUT.links.csv and left the OUT.rrd of the
    run before (with other cuts) beside them, named as this result's recording, without a
    word."""
    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    out, rrd = tmp_path / "clean.db", tmp_path / "clean.rrd"
    assert main(["clean-db", str(src), "--out", str(out), "--quiet"]) == 0
    recording = rrd.read_bytes()
    capsys.readouterr()
    assert main(["clean-db", str(src), "--out", str(out), "--overwrite", "--no-rerun",
                 "--quiet"]) == 0
    err = capsys.readouterr().err
    assert f"warning: {str(rrd)!r} beside {str(out)!r} is not this run's recording" in err
    assert rrd.read_bytes() == recording  # warned, not removed
    rrd.unlink()
    assert main(["clean-db", str(src), "--out", str(out), "--overwrite", "--no-rerun",
                 "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().err
