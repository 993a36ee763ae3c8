"""The evidence rule's stage (bounded label flooding, bundles on the small sets, the sync merge
on the large sets' links) against the rule's earlier form (the rows of Sec. III, then the
bundles on every set) and against ``sync`` run on the large sets' links alone."""

import numpy as np
import pytest
from consistency_graphs import instances
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from pipeline.association import AssociationGraph
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.rules import ResolutionRule, register, unregister
from pipeline.consistency.setlists import SET_BUNDLE_BYTES, bundle_budget, bundle_bytes_bound
from pipeline.errors import InputError
from pipeline.types import Links

SETTINGS = settings(max_examples=100, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])
ROWS = "evidence-after-rows"


@pytest.fixture(scope="module", autouse=True)
def rows_rule():
    """The rule in its earlier form: the rows of Sec. III, then one evidence pass on every
    conflictive set (the functions it still has), until a detection finds nothing."""
    register(ResolutionRule(
        name=ROWS, help="", title="", summary="", cases={},
        simulate="pipeline.consistency.evidence:evidence_pass",
        batched="pipeline.consistency.engines.batched_evidence:evidence_pass",
        start="pipeline.consistency.evidence:start_evidence_reliable",
        step="pipeline.consistency.evidence:evidence_round",
        done="pipeline.consistency.evidence:evidence_done",
        finish="pipeline.consistency.evidence:reexamine_sets", needs_evidence=True))
    yield
    unregister(ROWS)


def _poses(fpc, seed: int):
    rng = np.random.default_rng(seed)
    keypoints = [rng.uniform(0, 100, size=(m, 2)).astype(np.float32) for m in fpc]
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    return keypoints, [K @ np.c_[np.eye(3), rng.normal(0, 0.1, 3) + [0, 0, 5]] for _ in fpc]


def _set_sizes(fpc, links):
    """Association set (label) of every link and the size of each label's set."""
    labels, sizes, _ = _components(fpc, links)
    offsets = np.r_[0, np.cumsum(fpc)]
    lab = labels[offsets[links.cam_i] + links.feat_i]
    return lab, sizes


def _components(fpc, links):
    from pipeline.association import conflictive_labels

    return conflictive_labels(AssociationGraph(fpc, links))


def _sub(links: Links, keep: np.ndarray) -> Links:
    return Links(links.cam_i[keep], links.feat_i[keep], links.cam_j[keep], links.feat_j[keep],
                 links.quality[keep])


@SETTINGS
@given(inst=instances(max_n=7, max_feat=5), posed=st.booleans(), seed=st.integers(0, 2**32 - 1),
       budget=st.sampled_from([None, 10_000]))
def test_with_a_budget_above_every_set_the_stage_cuts_as_the_rule_after_the_rows(
        inst, posed, seed, budget):
    fpc, edges, links = inst
    kp, P = _poses(fpc, seed) if posed else (None, None)
    kw = dict(keypoints=kp, projections=P)
    new = resolve_conflicts(fpc, edges, links, resolution="evidence", bundle_budget=budget, **kw)
    old = resolve_conflicts(fpc, edges, links, resolution=ROWS, **kw)
    for f in ("deleted", "round", "iteration", "track_label"):
        np.testing.assert_array_equal(getattr(new, f), getattr(old, f), err_msg=f)
    np.testing.assert_array_equal(new.case == "", old.case == "")
    assert new.stats["large_sets"] == 0 and new.stats["merge_rounds"] == 0
    event(f"cut {int(new.deleted.sum())}")


@SETTINGS
@given(inst=instances(max_n=7, max_feat=5), budget=st.integers(1, 6), posed=st.booleans(),
       seed=st.integers(0, 2**32 - 1))
def test_with_a_small_budget_large_sets_get_the_merge_on_their_links(inst, budget, posed, seed):
    fpc, edges, links = inst
    kp, P = _poses(fpc, seed) if posed else (None, None)
    res = resolve_conflicts(fpc, edges, links, resolution="evidence", bundle_budget=budget,
                            keypoints=kp, projections=P)
    assert is_conflict_free(fpc, _sub(links, ~res.deleted))
    lab, sizes = _set_sizes(fpc, links)
    large = sizes[lab] > budget
    assert res.stats["large_sets"] == np.unique(lab[large]).size
    assert res.stats["bundle_budget"] == budget
    # the merge runs (and takes rounds) only when there is a large set
    assert (res.stats["merge_rounds"] > 0) == bool(large.any())
    event(f"large sets {res.stats['large_sets']}")
    # the large sets: sync's result on their links alone
    if large.any():
        sub = resolve_conflicts(fpc, edges, _sub(links, large), resolution="sync")
        np.testing.assert_array_equal(res.deleted[large], sub.deleted)
    # the small sets: the rule after the rows on their links alone
    if (~large).any():
        sub_kp = dict(keypoints=kp, projections=P)
        old = resolve_conflicts(fpc, edges, _sub(links, ~large), resolution=ROWS, **sub_kp)
        np.testing.assert_array_equal(res.deleted[~large], old.deleted)
        np.testing.assert_array_equal(res.round[~large], old.round)
    # every track is one association set of the kept links, named by its smallest feature
    kept = _sub(links, ~res.deleted)
    labels, _, _ = _components(fpc, kept)
    offsets = np.r_[0, np.cumsum(fpc)]
    named = res.track_label >= 0
    assert np.array_equal(named, np.isin(np.arange(offsets[-1]),
                                         np.r_[offsets[kept.cam_i] + kept.feat_i,
                                               offsets[kept.cam_j] + kept.feat_j]))
    smallest = {}
    for g in np.flatnonzero(named).tolist():
        smallest.setdefault(int(labels[g]), g)
    assert all(res.track_label[g] == smallest[int(labels[g])] for g in np.flatnonzero(named))


def test_the_default_budget_fits_a_sets_bundles_in_the_stated_bytes():
    for n in (2, 8, 101, 1000):
        B = bundle_budget(n)
        assert B * bundle_bytes_bound(n) <= SET_BUNDLE_BYTES or B == 2
        assert (B + 1) * bundle_bytes_bound(n) > SET_BUNDLE_BYTES or B == 2
    assert bundle_budget(101) == 152
    assert bundle_budget(101, 7) == 7


@pytest.mark.parametrize("bad", [0, -3, 2.5, True, "8", float("nan"), float("inf")])
def test_a_bad_bundle_budget_is_an_input_error(bad):
    links = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0])
    with pytest.raises(InputError, match="bundle_budget"):
        resolve_conflicts([1, 1, 1, 2], None, links, bundle_budget=bad)


@SETTINGS
@given(inst=instances(max_n=7, max_feat=5), budget=st.integers(1, 6), posed=st.booleans(),
       seed=st.integers(0, 2**32 - 1))
def test_left_to_the_caller_the_small_sets_stay_and_the_large_ones_are_merged(
        inst, budget, posed, seed):
    """``solve_small_sets=False``: no link of a set of at most ``B`` features is cut (the
    caller solves them, e.g. the online stage at each set's root); the large sets get the
    same merge as when the stage solves everything."""
    fpc, edges, links = inst
    kp, P = _poses(fpc, seed) if posed else (None, None)
    kw = dict(resolution="evidence", bundle_budget=budget, keypoints=kp, projections=P)
    left = resolve_conflicts(fpc, edges, links, solve_small_sets=False, **kw)
    full = resolve_conflicts(fpc, edges, links, **kw)
    lab, sizes = _set_sizes(fpc, links)
    large = sizes[lab] > budget
    assert not left.deleted[~large].any()
    np.testing.assert_array_equal(left.deleted[large], full.deleted[large])
    assert all(it["conflictive_sets"] == 0 for it in left.stats["per_iteration"])


def test_only_the_evidence_rule_leaves_its_small_sets_to_the_caller():
    links = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0])
    with pytest.raises(InputError, match="solve_small_sets=False.*'paper'"):
        resolve_conflicts([1, 1, 1, 2], None, links, resolution="paper", solve_small_sets=False)
