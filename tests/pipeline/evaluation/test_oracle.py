"""The resolution oracle: exact against brute force; the scores by hand."""

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.consistency.centralized import is_conflict_free, union_find_conflicts
from pipeline.evaluation.oracle import min_conflict_cut, oracle_cut, resolution_scores
from pipeline.types import Links

FIG1 = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0])  # camera 3 twice


@st.composite
def small_instances(draw):
    """A few cameras, one-to-one links on every camera pair, a random truth; ≤ 12 links."""
    n = draw(st.integers(2, 4))
    fpc = np.array([draw(st.integers(1, 3)) for _ in range(n)])
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    ci, fi, cj, fj = [], [], [], []
    for i, j in itertools.combinations(range(n), 2):
        k = int(min(fpc[i], fpc[j]))
        r, s = rng.permutation(fpc[i])[:k], rng.permutation(fpc[j])[:k]
        keep = rng.random(k) < 0.8
        ci += [i] * int(keep.sum())
        cj += [j] * int(keep.sum())
        fi += r[keep].tolist()
        fj += s[keep].tolist()
    links = Links(ci[:12], fi[:12], cj[:12], fj[:12])
    truth = rng.random(len(links)) < 0.8
    return fpc, links, truth


def brute_force_good_cuts(fpc, links, truth) -> int:
    """Fewest good links of conflictive sets to cut, after their spurious ones, by enumeration."""
    off = np.concatenate([[0], np.cumsum(fpc)])
    _, conflictive = union_find_conflicts(fpc, links)
    in_sets = conflictive[off[links.cam_i] + links.feat_i]
    base = ~(in_sets & ~truth)
    cand = np.flatnonzero(in_sets & truth)
    for k in range(cand.size + 1):
        for combo in itertools.combinations(cand.tolist(), k):
            kept = base.copy()
            kept[list(combo)] = False
            if is_conflict_free(fpc, links.subset(kept)):
                return k
    raise AssertionError("unreachable: cutting every link is conflict-free")


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(small_instances())
def test_oracle_is_exact(inst):
    fpc, links, truth = inst
    kept = oracle_cut(fpc, links, truth)
    assert is_conflict_free(fpc, links.subset(kept))
    sc = resolution_scores(fpc, links, truth, kept)
    assert sc["spurious_left"] == 0
    assert sc["spurious_cut"] == sc["spurious_in_sets"]
    assert sc["good_cut"] == brute_force_good_cuts(fpc, links, truth)


def test_oracle_on_fig1():
    # all good: one link must go; one spurious link in the cycle: that one alone
    assert (~oracle_cut([1, 1, 1, 2], FIG1, np.ones(4, bool))).sum() == 1
    truth = np.array([True, True, False, True])
    assert oracle_cut([1, 1, 1, 2], FIG1, truth).tolist() == [True, True, False, True]


def test_min_conflict_cut_two_disjoint_paths():
    # features 0 and 3 of camera 0 joined by two disjoint paths through cameras 1 and 2
    cam = np.array([0, 1, 2, 0, 1, 2])
    a = np.array([0, 1, 2, 0, 4, 5])
    b = np.array([1, 2, 3, 4, 5, 3])
    cut = min_conflict_cut(cam, a, b)
    assert cut.sum() == 2


def test_resolution_scores_by_hand():
    truth = np.array([True, False, True, True])
    kept = np.array([True, True, False, True])
    sc = resolution_scores([1, 1, 1, 2], FIG1, truth, kept)
    assert sc == {"good_cut": 1, "spurious_cut": 0, "spurious_in_sets": 1, "spurious_left": 1,
                  "links_in_sets": 4}


def test_truth_or_kept_of_another_length_is_refused():
    """A one-entry kept mask was broadcast over every link (scores of a mask never given);
    a truth of another length failed with numpy's broadcasting message."""
    import pytest

    from pipeline.errors import InputError

    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    truth = np.array([True, True, True, False])
    with pytest.raises(InputError, match=r"kept has shape \(1,\); give one entry per link \(4,\)"):
        resolution_scores([2, 1, 1, 1], links, truth, np.array([True]))
    with pytest.raises(InputError, match=r"truth has shape \(2,\)"):
        oracle_cut([2, 1, 1, 1], links, truth[:2])
    kept = oracle_cut([2, 1, 1, 1], links, truth)
    assert kept.tolist() == [True, True, True, False]
    assert resolution_scores([2, 1, 1, 1], links, truth, kept)["spurious_cut"] == 1


@pytest.mark.parametrize("truth, needle", [
    (np.array([1, 1, -1, 1], dtype=np.int8), r"truth\[2\] = -1: give booleans \(or 0 / 1\)"),
    ([1.0, 1.0, 0.4, 1.0], r"truth\[2\] = 0\.4"),
    (["y", "y", "n", "y"], r"truth\[0\] = 'y'"),
])
def test_truth_that_is_not_boolean_is_named_not_cast(truth, needle):
    # a cast to bool read -1 (a ledger's unknown link), 0.4 or 'n' as a good link
    from pipeline.errors import InputError

    links = Links([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0])
    with pytest.raises(InputError, match=needle):
        oracle_cut([2, 1, 1, 1], links, truth)
    with pytest.raises(InputError, match=needle):
        resolution_scores([2, 1, 1, 1], links, truth, [True] * 4)


def test_in_sets_is_checked_as_kept_is():
    """A list failed with "'list' object has no attribute 'sum'"; another length with numpy's
    broadcasting message; a -1 was read as a link in a set."""
    from pipeline.errors import InputError

    truth, kept = [True, False, True, True], [True, True, False, True]
    given = resolution_scores([1, 1, 1, 2], FIG1, truth, kept, in_sets=[True] * 4)
    assert given == resolution_scores([1, 1, 1, 2], FIG1, truth, kept)
    with pytest.raises(InputError, match=r"in_sets has shape \(3,\); give one entry per link"):
        resolution_scores([1, 1, 1, 2], FIG1, truth, kept, in_sets=[True] * 3)
    with pytest.raises(InputError, match=r"in_sets\[1\] = -1"):
        resolution_scores([1, 1, 1, 2], FIG1, truth, kept, in_sets=[1, -1, 1, 1])


@pytest.mark.parametrize("counts, needle", [
    ([1.5, 1, 1, 2], r"features_per_camera\[0\] = 1\.5 is not a whole-number id"),
    ([1, 1, 1, np.nan], r"features_per_camera\[3\] = nan"),
])
def test_oracle_cut_names_counts_that_are_not_whole_numbers(counts, needle):
    """A cast to int64 read 1.5 features as 1 and returned a cut of the truncated input."""
    from pipeline.errors import InputError

    with pytest.raises(InputError, match=needle):
        oracle_cut(counts, FIG1, np.ones(4, bool))


def test_min_conflict_cut_takes_lists_and_names_bad_ends():
    """Lists failed with AttributeError ('list' object has no attribute 'size')."""
    from pipeline.errors import InputError

    # a chain 0 - 1 - 2 - 3 - 4 whose ends 0 and 4 are features of camera 0
    assert min_conflict_cut([0, 1, 2, 3, 0], [0, 1, 2, 3], [1, 2, 3, 4]).sum() == 1
    with pytest.raises(InputError, match=r"a has 3 link ends and b 4"):
        min_conflict_cut([0, 1, 2, 3, 0], [0, 1, 2], [1, 2, 3, 4])
    with pytest.raises(InputError, match=r"link 3 \(3, 9\) names a node outside 0\.\.4"):
        min_conflict_cut([0, 1, 2, 3, 0], [0, 1, 2, 3], [1, 2, 3, 9])
    with pytest.raises(InputError, match=r"b\[0\] = 1\.5"):
        min_conflict_cut([0, 1, 2, 3, 0], [0, 1, 2, 3], [1.5, 2, 3, 4])
