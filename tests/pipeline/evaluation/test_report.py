"""Report sections read from a hand-built ledger, against hand-counted answers."""

import numpy as np

from pipeline.evaluation.report import (
    PAPER_TABLE_III_IV,
    association_counts,
    fusion_section,
    report_markdown,
    resolution_section,
)
from pipeline.types import LinkLedger, Links

# paper Fig. 1 plus a link (1,1)-(2,1) outside the conflictive set
LINKS = Links(cam_i=[0, 0, 1, 2, 1], feat_i=[0, 0, 0, 0, 1], cam_j=[3, 1, 2, 3, 2],
              feat_j=[1, 0, 0, 0, 1])
M = [1, 2, 2, 2]


def _ledger(truth=None):
    ledger = LinkLedger.all_kept(LINKS, truth=truth)
    ledger.cut(np.array([1]), "resolution", 3, iteration=1, case="c")
    ledger.cut(np.array([4]), "fusion-outlier", 40)
    return ledger


def test_sections_with_ground_truth():
    ledger = _ledger(truth=np.array([1, 0, 1, 1, 1]))
    stats = {"iterations": 1, "detection_rounds": 5, "resolution_rounds": 3, "messages": 12,
             "bytes": 480, "max_robot_memory_bytes": 64, "protocol": "paper"}
    r = resolution_section(ledger, stats)
    assert (r["deleted_links"], r["good_deleted"], r["spurious_deleted"]) == (1, 0, 1)
    assert r["deleted_by_case"] == {"b": 0, "c": 1} and r["details"] == {"protocol": "paper"}
    f = fusion_section(ledger, {"enabled": True, "rounds": 40})
    assert f == {"enabled": True, "rounds": 40, "cut_links": 1, "cut_spurious": 0, "cut_good": 1}
    before = association_counts(M, LINKS, ledger.good, 2)
    assert (before["conflictive_sets"], before["good_links"], before["spurious_links"],
            before["missing_links"], before["precision"]) == (1, 4, 1, 2, 0.8)
    md = report_markdown({"before": before, "after": association_counts(
        M, LINKS.subset(ledger.kept), ledger.good[ledger.kept], 2), "resolution": r,
        "fusion": f})
    assert "| Conflictive sets (c) | 1 | 0 |" in md and "| spurious deleted | 1 |" in md
    assert "| links cut by fusion (fusion-outlier) | 1 |" in md
    off = fusion_section(ledger, {"enabled": False, "reason": "disabled by option"})
    md = report_markdown({"before": before, "after": before, "resolution": r, "fusion": off})
    assert "| fusion | not run (disabled by option) |" in md and "links cut by fusion" not in md


def test_sections_without_ground_truth_leave_good_and_spurious_out():
    ledger = _ledger()
    r = resolution_section(ledger, {})
    assert "good_deleted" not in r and r["deleted_links"] == 1
    assert fusion_section(ledger, {}) == {"cut_links": 1}
    assert "good_links" not in association_counts(M, LINKS, None, None)


def test_paper_tables_have_one_value_per_formation():
    assert all(len(v) == 4 for v in PAPER_TABLE_III_IV.values())
    assert PAPER_TABLE_III_IV["Deleted links"] == (2, 26, 46, 131)


def test_sets_well_and_wrongly_solved_as_table_iv_counts_them():
    """Table IV: a conflictive set is well solved when none of the links the algorithm keeps
    in it is spurious (links cut by fusion came after it: still kept by the algorithm)."""
    inside = np.array([True, True, True, True, False])  # Fig. 1's set; link 4 outside it
    for truth, want in ((np.array([1, 0, 1, 1, 0]), (1, 0)),   # the spurious one was cut
                        (np.array([0, 1, 1, 1, 1]), (0, 1)),   # a spurious one was kept
                        (np.array([1, 1, 1, 1, 1]), (1, 0))):
        ledger = LinkLedger.all_kept(LINKS, truth=truth, conflictive_before=inside)
        ledger.cut(np.array([1]), "resolution", 3, iteration=1, case="c")
        ledger.cut(np.array([0]), "fusion-outlier", 40)
        r = resolution_section(ledger, {})
        assert (r["sets_well_solved"], r["sets_wrongly_solved"]) == want, truth
    # without conflictive sets, nothing to solve
    r = resolution_section(_ledger(truth=np.array([1, 0, 1, 1, 1])), {})
    assert (r["sets_well_solved"], r["sets_wrongly_solved"]) == (0, 0)


def test_paper_table_iv_rows_are_keyed_by_what_they_count():
    """The text beside Table IV: its fifth row counts the spurious links deleted, its sixth
    the good ones; they were keyed the other way round."""
    assert PAPER_TABLE_III_IV["Spurious deleted links"] == (1, 2, 19, 43)
    assert PAPER_TABLE_III_IV["Good deleted links"] == (1, 24, 27, 88)
    assert (PAPER_TABLE_III_IV["Inconsistencies well solved"],
            PAPER_TABLE_III_IV["Inconsistencies wrongly solved"]) == ((1, 20, 24, 55),
                                                                      (1, 2, 7, 17))


def test_sets_solved_count_each_of_two_conflictive_sets_once():
    # set A: Fig. 1 (camera 3 twice); set B: 0:1-1:1-2:1-0:2 (camera 0 twice)
    links = Links(cam_i=[0, 0, 1, 2, 0, 1, 0], feat_i=[0, 0, 0, 0, 1, 1, 2],
                  cam_j=[3, 1, 2, 3, 1, 2, 2], feat_j=[1, 0, 0, 0, 1, 1, 1])
    inside = np.ones(7, dtype=bool)
    # links 0 and 1 of A spurious and kept: A wrongly solved (once, not twice); link 6 of B
    # spurious, lost with its robot: B well solved
    ledger = LinkLedger.all_kept(links, truth=np.array([0, 0, 1, 1, 1, 1, 0]),
                                 conflictive_before=inside)
    ledger.cut(np.array([6]), "robot-lost", 2)
    assert resolution_section(ledger, {})["sets_wrongly_solved"] == 1
    assert resolution_section(ledger, {})["sets_well_solved"] == 1
    # link 6 kept instead: both sets wrongly solved
    ledger = LinkLedger.all_kept(links, truth=np.array([0, 0, 1, 1, 1, 1, 0]),
                                 conflictive_before=inside)
    r = resolution_section(ledger, {})
    assert (r["sets_well_solved"], r["sets_wrongly_solved"]) == (0, 2)


def test_baseline_rows_count_what_each_mask_cut():
    from pipeline.evaluation.report import baselines_section

    good = np.array([True, False, True, True, True])
    masks = {"cut_two": np.array([True, False, True, False, True]),   # 1 spurious, 1 good
             "keep_all": np.ones(5, dtype=bool)}
    rows = baselines_section(M, LINKS, good, masks=masks)
    assert (rows["cut_two"]["deleted_links"], rows["cut_two"]["good_deleted"],
            rows["cut_two"]["spurious_deleted"]) == (2, 1, 1)
    assert (rows["cut_two"]["good_links"], rows["cut_two"]["spurious_links"]) == (3, 0)
    assert (rows["keep_all"]["deleted_links"], rows["keep_all"]["good_deleted"],
            rows["keep_all"]["spurious_deleted"]) == (0, 0, 0)
