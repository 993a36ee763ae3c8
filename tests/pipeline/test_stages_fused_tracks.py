"""Fused landmarks of the stage chain named in the numbering of every camera, also when a
robot crashed between the consistency stage and fusion (pipeline.stages.clean_association)."""

import numpy as np
import pytest

import data_synth
from data_synth.ground_truth import points_from_keypoints
from pipeline.evaluation.report import fused_point_errors
from pipeline.faults import FaultConfig
from pipeline.fusion.landmarks import tracks_of
from pipeline.progress import StageTimer
from pipeline.stages import clean_association, extract_and_match

#: reprojection error [px] under which a fused landmark lies on a keypoint of its track
#: (the rendered keypoints are within 2 px of their ground truth, tol_px of run-formation)
REPROJ_TOL_PX = 2.0
#: distance [scene units] within which two computations of one error figure agree
FIGURE_TOL = 1e-9


@pytest.fixture(scope="module")
def formation_a():
    formation = data_synth.render("a", seed=0, size=(320, 240))
    feats, _, links = extract_and_match(formation.views, formation.comm_edges, "sift", 500,
                                        StageTimer(verbose=False))
    return formation, feats, links


def _project(view, X):
    x = (view.K @ (np.asarray(view.R) @ X.T + np.asarray(view.t).reshape(3, 1))).T
    return x[:, :2] / x[:, 2:]


@pytest.mark.parametrize("crash", [(2, 21), (1, 21)])
def test_fused_landmarks_of_a_crash_before_fusion_lie_on_their_tracks(formation_a, crash):
    formation, feats, links = formation_a
    views = formation.views
    cleaning = clean_association(views, feats, formation.comm_edges, links,
                                 faults=FaultConfig(crash=(crash,)), resolution="paper")
    robot = crash[0]
    assert cleaning.fusion_stats["crashed_before_fusion"] == [robot]  # the case under test
    ledger = cleaning.ledger
    resolved = links.subset(ledger.kept | (ledger.reason == "fusion-outlier"))
    m = np.array([len(f) for f in feats])
    off = np.concatenate([[0], np.cumsum(m)])
    track_of, _ = tracks_of(m, resolved)
    cam_of = np.repeat(np.arange(len(m)), m)
    pts, ids = cleaning.fused_points, cleaning.fused_track_ids
    assert len(pts) == len(ids) > 100
    # direct: project each fused landmark into the surviving cameras of the track its id
    # names, onto the keypoints of that track's features there
    errors = []
    for X, b in zip(pts, ids, strict=True):
        g = np.flatnonzero((track_of == b) & (cam_of != robot))
        uv = np.stack([_project(views[c], X[None])[0] for c in cam_of[g]])
        kp = np.stack([feats[c].keypoints[f - off[c]] for c, f in zip(cam_of[g], g, strict=True)])
        errors.append(np.median(np.linalg.norm(uv - kp, axis=1)))
    errors = np.array(errors)
    assert np.mean(errors <= REPROJ_TOL_PX) >= 0.9, np.percentile(errors, [50, 90])

    # the report's figures: each landmark against the truth of the features it was fused from
    gt_points = [points_from_keypoints(v, f.keypoints)[0] for v, f in zip(views, feats, strict=True)]
    figures = fused_point_errors(views, feats, resolved, pts, ids, gt_points,
                                 fused_track_features=cleaning.fused_track_features)
    all_gt = np.concatenate(gt_points)
    direct = []
    for X, b, feats_of_point in zip(pts, ids, cleaning.fused_track_features, strict=True):
        assert robot not in cam_of[feats_of_point]  # only what the survivors fused
        assert (track_of[feats_of_point] == b).all()  # in the track of the kept links
        G = all_gt[feats_of_point]
        G = G[np.isfinite(G).all(axis=1)]
        if len(G):
            medoid = G[np.argmin(np.linalg.norm(G[:, None] - G[None], axis=-1).sum(1))]
            direct.append(np.linalg.norm(X - medoid))
    assert figures["p90_error_vs_ground_truth"] == pytest.approx(
        np.percentile(direct, 90), abs=FIGURE_TOL)
    assert figures["median_error_vs_ground_truth"] == pytest.approx(
        np.median(direct), abs=FIGURE_TOL)


def test_per_robot_fusion_figures_of_a_crash_before_fusion_are_by_robot_id(formation_a):
    """Fusion runs on the survivors renumbered 0..k-1; the report's per-robot figures name
    every robot of the team, None for the one that took no part."""
    from pipeline.stages import consistency_stage, fusion_stage, ledger_from_consistency

    formation, feats, links = formation_a
    views, edges = formation.views, formation.comm_edges
    faults = FaultConfig(crash=((2, 21),))
    cleaning = clean_association(views, feats, edges, links, faults=faults, resolution="paper")
    fs = cleaning.fusion_stats
    assert fs["crashed_before_fusion"] == [2]
    survivors = [0, 1, 3, 4, 5]
    # direct: the survivors' fusion on the consistency stage's decisions, in its own numbering
    m = [len(f) for f in feats]
    res, _ = consistency_stage(m, edges, links, faults, resolution="paper")
    fr, _ = fusion_stage(ledger_from_consistency(res), views, feats, edges,
                         cameras=np.array(survivors), track_labels=res.track_label)
    for key in ("robot_sigma_px", "noise_residuals"):
        assert len(fs[key]) == len(views) and fs[key][2] is None
        assert [fs[key][k] for k in survivors] == fr.stats[key]


def test_a_crash_that_leaves_no_fused_landmark_reports_none(formation_a):
    """Robots 1 and 3 survive, no neighbours of each other: fusion runs and fuses nothing."""
    formation, feats, links = formation_a
    views = formation.views
    faults = FaultConfig(crash=tuple((r, 21) for r in (0, 2, 4, 5)))
    cleaning = clean_association(views, feats, formation.comm_edges, links, faults=faults,
                                 resolution="paper")
    assert cleaning.fusion_stats["enabled"] and cleaning.fusion_stats["tracks_fused"] == 0
    assert len(cleaning.fused_track_ids) == len(cleaning.fused_track_features) == 0
    gt_points = [points_from_keypoints(v, f.keypoints)[0] for v, f in zip(views, feats, strict=True)]
    ledger = cleaning.ledger
    figures = fused_point_errors(views, feats, links.subset(ledger.kept), cleaning.fused_points,
                                 cleaning.fused_track_ids, gt_points,
                                 fused_track_features=cleaning.fused_track_features)
    assert figures["fused_points"] == 0 and figures["p90_error_vs_ground_truth"] is None
