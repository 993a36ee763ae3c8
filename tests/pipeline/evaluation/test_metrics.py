import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.evaluation.metrics import PairwiseTruth, association_pairs, pairwise_scores
from pipeline.types import Links


def test_transitive_pairs_are_implied():
    # chain 0:0 - 1:0 - 2:0 implies the pair 0:0 - 2:0 as well
    links = Links([0, 1], [0, 0], [1, 2], [0, 0])
    pairs = association_pairs([1, 1, 1], links)
    assert pairs.tolist() == [[0, 1], [0, 2], [1, 2]]


def test_scores_hand_computed():
    predicted = np.array([[0, 1], [0, 2], [1, 2]])
    truth = np.array([[1, 0], [3, 4]])  # order within a pair does not matter
    s = pairwise_scores(predicted, truth, m_total=5)
    assert s["correct_pairs"] == 1
    assert np.isclose(s["precision"], 1 / 3)
    assert np.isclose(s["recall"], 1 / 2)
    assert np.isclose(s["f1"], 2 * (1 / 3) * (1 / 2) / (1 / 3 + 1 / 2))


def test_empty_prediction_scores_zero():
    s = pairwise_scores(np.zeros((0, 2), int), np.array([[0, 1]]), m_total=2)
    assert (s["precision"], s["recall"], s["f1"]) == (0.0, 0.0, 0.0)


def _pairs_set_by_set(m, links):
    """Reference: the pairs of every association set, one set at a time."""
    from pipeline.association import association_sets

    _, tracks = association_sets(m, links)
    pairs = [(min(a, b), max(a, b)) for t in tracks for k, a in enumerate(t.tolist())
             for b in t.tolist()[k + 1:]]
    return sorted(pairs)


def test_association_pairs_match_set_by_set_enumeration():
    rng = np.random.default_rng(7)
    m = [40, 35, 50, 45]
    for _ in range(20):
        rows = []  # one-to-one per camera pair (Assumption 2.2), random sizes
        for i in range(4):
            for j in range(i + 1, 4):
                k = int(rng.integers(0, 25))
                rows += zip([i] * k, rng.permutation(m[i])[:k], [j] * k,
                            rng.permutation(m[j])[:k], strict=True)
        ci, fi, cj, fj = (np.array(c, dtype=np.int64) for c in zip(*rows, strict=True))
        links = Links(ci, fi, cj, fj)
        got = association_pairs(m, links)
        assert got.dtype == np.int64
        assert [tuple(p) for p in got.tolist()] == _pairs_set_by_set(m, links)


@st.composite
def _links_and_truth(draw):
    """Features per camera, one-to-one links per camera pair, and true pairs (some repeated,
    some reversed, some between features of one camera)."""
    n = draw(st.integers(2, 5))
    m = draw(st.lists(st.integers(0, 12), min_size=n, max_size=n))
    off = np.concatenate([[0], np.cumsum(m)])
    rows = []
    for i in range(n):
        for j in range(i + 1, n):
            k = draw(st.integers(0, min(m[i], m[j])))
            fi = draw(st.permutations(range(m[i])))[:k]
            fj = draw(st.permutations(range(m[j])))[:k]
            rows += zip([i] * k, fi, [j] * k, fj, strict=True)
    cols = list(zip(*rows, strict=True)) if rows else [(), (), (), ()]
    links = Links(*(np.array(c, dtype=np.int64) for c in cols))
    total = int(off[-1])
    truth = draw(st.lists(st.tuples(st.integers(0, max(total - 1, 0)),
                                    st.integers(0, max(total - 1, 0))), max_size=40)) \
        if total else []
    truth = [p for p in truth if p[0] != p[1]]  # a feature paired with itself is refused
    return m, links, np.array(truth, dtype=np.int64).reshape(-1, 2), total


@settings(max_examples=150, deadline=None)
@given(_links_and_truth())
def test_pairwise_truth_scores_equal_the_scores_of_the_listed_pairs(case):
    m, links, truth, total = case
    assert PairwiseTruth(truth, total).scores(m, links) == \
        pairwise_scores(association_pairs(m, links), truth, total)


def test_pairwise_truth_refuses_another_feature_count():
    links = Links([0], [0], [1], [0])
    with pytest.raises(ValueError, match="3 features scored on 2"):
        PairwiseTruth(np.array([[0, 1]]), 3).scores([1, 1], links)


def test_pairs_outside_m_total_or_not_pairs_are_refused():
    """A pair naming a feature past m_total shares its key with another pair: (0, 9) was
    scored as the true pair (1, 3) with m_total 5 (precision 1.0)."""
    from pipeline.errors import InputError

    with pytest.raises(InputError, match=r"predicted pairs: row 0 \[0, 9\] names a feature "
                                         r"outside 0..4"):
        pairwise_scores(np.array([[0, 9]]), np.array([[1, 3]]), 5)
    with pytest.raises(InputError, match=r"truth pairs: give a \(P, 2\) array .* shape \(2,\)"):
        pairwise_scores(np.array([[0, 1]]), np.array([0, 1]), 5)
    assert pairwise_scores([[1, 0]], [[0, 1]], 5)["f1"] == 1.0
    assert pairwise_scores(np.zeros((0, 2), int), [], 5)["predicted_pairs"] == 0


def test_pairwise_truth_refuses_a_true_pair_past_the_features_as_pairwise_scores_does():
    # (0, 6) of 3 features wrapped to the key of (1, 2): counted as found, recall 1.0
    import pytest

    from pipeline.errors import InputError
    from pipeline.types import Links

    chain = Links([0, 1], [0, 0], [1, 2], [0, 0])
    truth = np.array([[0, 1], [0, 6]])
    needle = r"truth pairs: row 1 \[0, 6\] names a feature outside 0\.\.2"
    with pytest.raises(InputError, match=needle):
        pairwise_scores(association_pairs([1, 1, 1], chain), truth, 3)
    with pytest.raises(InputError, match=needle):
        PairwiseTruth(truth, 3).scores([1, 1, 1], chain)


def test_a_feature_count_that_is_not_a_whole_number_is_named():
    # None failed with a TypeError inside the range check; 5.5 let feature 5 count as existing
    import pytest

    from pipeline.errors import InputError

    for m_total in (None, 5.5, -1):
        with pytest.raises(InputError, match=f"m_total {m_total!r}: give the number of features"):
            pairwise_scores(np.array([[0, 1]]), np.array([[0, 1]]), m_total)
        with pytest.raises(InputError, match=f"m_total {m_total!r}: give the number of features"):
            PairwiseTruth(np.array([[0, 1]]), m_total)


def test_a_feature_paired_with_itself_is_refused():
    # (1, 1) counted as a predicted pair (precision 0 of 1), and as a true pair in truth
    import pytest

    from pipeline.errors import InputError
    from pipeline.types import Links

    with pytest.raises(InputError, match=r"predicted pairs: row 0 \[1, 1\] pairs feature 1 "
                                         "with itself"):
        pairwise_scores(np.array([[1, 1]]), np.array([[1, 0]]), 5)
    with pytest.raises(InputError, match=r"truth pairs: row 1 \[2, 2\] pairs feature 2 with"):
        pairwise_scores(np.array([[1, 0]]), np.array([[1, 0], [2, 2]]), 5)
    with pytest.raises(InputError, match=r"truth pairs: row 0 \[0, 0\] pairs feature 0 with"):
        PairwiseTruth(np.array([[0, 0]]), 3).scores([1, 1, 1], Links([0], [0], [1], [0]))
