"""LinkLedger: the one per-link record of a run."""

import re

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.types import LinkLedger, Links


def _links():
    return Links([0, 0, 1], [0, 1, 2], [1, 2, 2], [3, 4, 5])


def test_all_kept_then_cut_by_two_stages():
    ledger = LinkLedger.all_kept(_links())
    assert ledger.kept.tolist() == [True, True, True] and ledger.good is None
    ledger.cut(np.array([False, True, False]), "resolution", 2, iteration=1, case="b")
    ledger.cut(np.array([2]), "fusion-outlier", 7)
    assert ledger.status.tolist() == ["kept", "deleted", "deleted"]
    assert ledger.reason.tolist() == ["", "resolution", "fusion-outlier"]
    assert ledger.round.tolist() == [-1, 2, 7]
    assert ledger.iteration.tolist() == [-1, 1, -1]  # fusion leaves iteration and case alone
    assert ledger.case.tolist() == ["", "b", ""]
    assert len(ledger) == 3 and ledger.kept.tolist() == [True, False, False]


def test_truth_codes_give_the_good_links():
    ledger = LinkLedger.all_kept(_links(), truth=np.array([1, 0, 1]))
    assert ledger.good.tolist() == [True, False, True]


@pytest.mark.parametrize("field,value,match", [
    ("status", ["kept", "gone", "kept"], "status must be 'kept' or 'deleted'"),
    ("round", [-1, -1], "round has length 2, expected one per link"),
    ("truth", [1], "truth has length 1"),
])
def test_a_malformed_ledger_is_refused(field, value, match):
    L = 3
    args = dict(links=_links(), status=["kept"] * L, reason=[""] * L, round=[-1] * L,
                iteration=[-1] * L, case=[""] * L)
    args[field] = value
    with pytest.raises(InputError, match=match):  # not a bare ValueError
        LinkLedger(**args)


@pytest.mark.parametrize("ids, shown", [
    ([True, False], "True"),            # a boolean mask given for ids
    (["0", "1"], "'0'"),                # text
    ([0, None], "None"),
    ([0, 2**70], str(2**70)),           # a Python int past int64
    ([1 + 2j, 0], "(1+2j)"),
])
def test_ids_that_are_not_whole_numbers_are_refused_and_named(ids, shown):
    with pytest.raises(ValueError, match=rf"Links: cam_i\[\d\] = {re.escape(shown)} is not a "
                                         "whole-number id"):
        Links(ids, [0, 0], [1, 1], [0, 1])


def test_ragged_ids_are_refused_and_object_ids_taken():
    with pytest.raises(ValueError, match="Links: cam_i must be a flat sequence"):
        Links([[0], [0, 1]], [0, 0], [1, 1], [0, 1])
    links = Links(np.array([0, 0], dtype=object), [0, 1.0], [1, 1], [0, 1])
    assert links.cam_i.dtype == np.int64 and links.feat_i.tolist() == [0, 1]
    assert Links(np.array([], dtype=bool), [], [], []).cam_i.dtype == np.int64


def test_ids_given_as_a_table_are_refused_with_their_shape():
    from pipeline.association import AssociationGraph

    with pytest.raises(ValueError, match=r"Links: cam_i must be a flat .* shape \(2, 1\)"):
        Links([[0], [0]], [0, 1], [1, 1], [0, 1])
    # [[2, 1], [1, 1]] was taken as four cameras
    with pytest.raises(ValueError, match=r"features_per_camera must be a flat .* shape \(2, 2\)"):
        AssociationGraph([[2, 1], [1, 1]], Links([0], [0], [1], [0]))
    assert Links(np.int64(0), 0, 1, 0).cam_i.tolist() == [0]  # a scalar is one id


def test_links_of_mismatched_lengths_are_refused_as_input_errors_naming_the_lengths():
    from pipeline.errors import InputError

    with pytest.raises(InputError, match="cam_i 3, feat_i 4, cam_j 4, feat_j 4"):
        Links([0, 1, 2], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    with pytest.raises(InputError, match=r"Links: cam_i\[0\] = 'a' is not a whole-number id"):
        Links(["a"], [0], [1], [0])


@pytest.mark.parametrize("quality, match", [
    ([1.0, 1.0], r"quality has length 2, expected 3"),
    (["a", "b", "c"], r"quality must be numbers.*'a'"),
    ([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]], r"quality must be a flat .* shape \(2, 3\)"),
    (np.ones((3, 1)), r"quality must be a flat .* shape \(3, 1\)"),
])
def test_a_quality_that_is_not_one_number_per_link_is_refused(quality, match):
    from pipeline.errors import InputError

    with pytest.raises(InputError, match=match):
        Links(*_links_columns(), quality)


def _links_columns():
    links = _links()
    return links.cam_i, links.feat_i, links.cam_j, links.feat_j


def test_links_subset_refuses_what_would_select_other_links():
    """A mask of 0 / 1 integers was read as indices (links 1, 0, 1, 1: link 1 three times);
    a boolean mask of another length or an index past the links ended in numpy's IndexError."""
    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    with pytest.raises(InputError, match=r"an index is given more than once .* give booleans"):
        links.subset(np.array([1, 0, 1, 1]))
    with pytest.raises(InputError, match=r"a mask of shape \(3,\) for 4 links"):
        links.subset([True, False, True])
    with pytest.raises(InputError, match=r"index 7 is outside 0\.\.3 \(4 links\)"):
        links.subset([0, 7])
    with pytest.raises(InputError, match=r"not an array of dtype float64"):
        links.subset([0.5])
    assert links.subset(np.array([1, 0, 1, 1], dtype=bool)).feat_i.tolist() == [0, 0, 1]
    assert links.subset([3, 0]).cam_j.tolist() == [3, 1]
    assert len(links.subset([])) == 0 and len(links.subset(np.zeros(4, bool))) == 0


def test_ledger_cut_refuses_a_mask_of_integers_read_as_indices():
    """cut(np.array([1, 0, 0, 0])) cut links 1 and 0, not link 0."""
    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    ledger = LinkLedger.all_kept(links)
    with pytest.raises(InputError, match=r"an index is given more than once"):
        ledger.cut(np.array([1, 0, 0, 0]), "resolution", 1)
    assert ledger.status.tolist() == ["kept"] * 4
    ledger.cut(np.array([2]), "resolution", 1)
    ledger.cut(np.array([True, False, False, False]), "fusion-outlier", 2)
    assert ledger.status.tolist() == ["deleted", "kept", "deleted", "kept"]
