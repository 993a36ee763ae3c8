"""The stage chain of pipeline.stages: the consistency entry (with faults) and the fusion stage."""

import re

import numpy as np
from fusion.test_landmarks import planted_rig

from pipeline.consistency import resolve_conflicts
from pipeline.faults import FaultConfig
from pipeline.stages import consistency_stage, fusion_stage, ledger_from_consistency
from pipeline.types import LinkLedger, Links

FIG1 = Links(cam_i=[0, 0, 1, 2], feat_i=[0, 0, 0, 0], cam_j=[3, 1, 2, 3], feat_j=[1, 0, 0, 0])


def test_consistency_stage_is_resolve_conflicts_without_faults():
    res, faults = consistency_stage([1, 1, 1, 2], None, FIG1, resolution="paper")
    direct = resolve_conflicts([1, 1, 1, 2], None, FIG1, resolution="paper")
    assert faults is None and res.deleted.tolist() == direct.deleted.tolist()
    ledger = ledger_from_consistency(res)
    assert ledger.status.tolist().count("deleted") == 1  # paper Fig. 1: one link cut
    assert ledger.reason[res.deleted].tolist() == ["resolution"]
    assert ledger.case[res.deleted].tolist() == direct.case[direct.deleted].tolist()


def test_consistency_stage_with_faults_reports_them_against_a_fault_free_run():
    fpc = [1, 1, 1, 2]
    res, faults = consistency_stage(fpc, None, FIG1, FaultConfig(crash=((1, 1),)),
                                    resolution="paper")
    assert faults["injected"]["crash"] == ["1@1"] and faults["crashed"] == {"1": 1}
    fault_free = resolve_conflicts(fpc, None, FIG1, resolution="paper").stats
    assert faults["fault_free_messages"] == fault_free["messages"]
    assert faults["extra_messages"] == faults["messages"] - fault_free["messages"]
    assert "messages_dropped" in faults and res.stats["protocol"] == "reliable"


def test_fusion_stage_cuts_the_planted_observation_in_the_ledger():
    views, feats, links, edges, _ = planted_rig()
    planted = ((links.cam_i == 2) & (links.feat_i == 30)) | ((links.cam_j == 2) & (links.feat_j == 30))
    ledger = LinkLedger.all_kept(links)
    fr, n_cut = fusion_stage(ledger, views, feats, edges)
    assert n_cut == planted.sum() == (ledger.reason == "fusion-outlier").sum()
    assert (ledger.status[planted] == "deleted").all() and ledger.kept[~planted].all()
    assert (ledger.round[planted] == fr.stats["rounds"]).all()


def test_fusion_stage_among_posed_cameras_leaves_the_others_alone():
    views, feats, links, edges, _ = planted_rig()
    ledger = LinkLedger.all_kept(links)
    fr, n_cut = fusion_stage(ledger, views, feats, edges, cameras=np.array([0, 1, 3]))
    # camera 2 holds the planted observation and takes no part: nothing is cut
    assert n_cut == 0 and ledger.kept.all()
    assert fr.stats["tracks_fused"] == 30


def test_the_features_stage_line_says_the_budget_of_the_images():
    import io

    from pipeline.progress import StageTimer
    from pipeline.stages import extract_and_match
    from pipeline.types import View

    rng = np.random.default_rng(0)
    views = [View(f"v{k}", rng.integers(0, 255, size=(640, 800), dtype=np.uint8), np.eye(3))
             for k in range(2)]
    for budget, line in ((None, "[features] sift, at most 3333 per image (2000 per 640x480 "
                                "pixels, from 2000 to 8192)"),
                         (500, "[features] sift, at most 500 per image")):
        out = io.StringIO()
        extract_and_match(views, np.zeros((0, 2), dtype=np.int64), "sift", budget,
                          StageTimer(stream=out))
        assert line in out.getvalue().splitlines()[0], out.getvalue()


def test_consistency_stage_names_counts_that_are_not_whole_numbers():
    """A cast to int64 read 1.5 features as 1 and resolved the truncated input (nan: numpy's
    'cannot convert float NaN to integer')."""
    import pytest

    from pipeline.errors import InputError

    for counts, needle in (([1.5, 1, 1, 2], r"features_per_camera\[0\] = 1\.5 is not a whole"),
                           ([1, 1, 1, np.nan], r"features_per_camera\[3\] = nan")):
        with pytest.raises(InputError, match=needle):
            consistency_stage(counts, None, FIG1)


def test_a_merge_radius_that_is_not_a_number_is_named():
    """Text failed with numpy's "ufunc 'isfinite' not supported for the input types"; True
    was read as a radius of 1 px."""
    import pytest

    from pipeline.errors import InputError
    from pipeline.stages import check_merge_radius, merge_radius_for

    for bad in ("2", True, [2.0]):
        with pytest.raises(InputError, match=rf"--merge-radius {re.escape(repr(bad))}: expected "
                                             r"a number of pixels"):
            merge_radius_for("evidence", bad)
        with pytest.raises(InputError, match=r"expected a number of pixels"):
            check_merge_radius(bad, [(64, 48)], "the images")
    assert merge_radius_for("evidence", np.float32(1.5)) == 1.5
    assert merge_radius_for("evidence", 3) == 3.0
