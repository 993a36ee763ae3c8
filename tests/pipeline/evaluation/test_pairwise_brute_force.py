"""Pairwise precision / recall / F1 against a reference written from the definition: every
unordered pair of two features in one association set (the transitive closure of the links),
enumerated with itertools, scored as a set against the set of unordered true pairs."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.evaluation.metrics import PairwiseTruth, association_pairs, pairwise_scores
from pipeline.types import Links


def _reference(predicted: set, truth: set) -> dict:
    correct = len(predicted & truth)
    precision = correct / len(predicted) if predicted else 0.0
    recall = correct / len(truth) if truth else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": precision, "recall": recall, "f1": f1,
            "predicted_pairs": len(predicted), "true_pairs": len(truth),
            "correct_pairs": correct}


def _closure_pairs(m, rows) -> set:
    """Unordered feature pairs of every connected component of the links (global ids)."""
    off = np.concatenate([[0], np.cumsum(m)]).tolist()
    parent = list(range(off[-1]))

    def find(x):
        while parent[x] != x:
            x = parent[x]
        return x

    for ci, fi, cj, fj in rows:
        a, b = find(off[ci] + fi), find(off[cj] + fj)
        parent[a] = b
    sets: dict = {}
    for x in range(off[-1]):
        sets.setdefault(find(x), []).append(x)
    return {frozenset(p) for s in sets.values() for p in itertools.combinations(s, 2)}


def _close(got: dict, want: dict) -> bool:
    return all(got[k] == want[k] for k in ("predicted_pairs", "true_pairs", "correct_pairs")) \
        and all(abs(got[k] - want[k]) <= 1e-12 for k in ("precision", "recall", "f1"))


@st.composite
def _pair_lists(draw):
    """A feature count and two lists of pairs of distinct features, with repeats and both
    orders of one pair."""
    total = draw(st.integers(2, 9))
    pair = st.tuples(st.integers(0, total - 1), st.integers(0, total - 1)) \
        .filter(lambda p: p[0] != p[1])
    predicted = draw(st.lists(pair, max_size=25))
    truth = draw(st.lists(pair, max_size=25))
    return total, predicted, truth


@settings(max_examples=200, deadline=None)
@given(_pair_lists())
def test_pairwise_scores_count_each_unordered_pair_once(case):
    total, predicted, truth = case
    got = pairwise_scores(np.array(predicted, dtype=np.int64).reshape(-1, 2),
                          np.array(truth, dtype=np.int64).reshape(-1, 2), total)
    want = _reference({frozenset(p) for p in predicted}, {frozenset(p) for p in truth})
    assert _close(got, want), (got, want)


def test_a_predicted_pair_listed_twice_or_reversed_is_one_pair():
    # (0, 1) three times in two orders and (2, 3) once: two predicted pairs, one of them true
    predicted = np.array([[0, 1], [1, 0], [0, 1], [2, 3]])
    s = pairwise_scores(predicted, np.array([[0, 1], [1, 2]]), m_total=4)
    assert (s["predicted_pairs"], s["correct_pairs"], s["true_pairs"]) == (2, 1, 2)
    assert (s["precision"], s["recall"], s["f1"]) == (0.5, 0.5, 0.5)


@st.composite
def _any_links(draw):
    """Features per camera, links one-to-one within each camera pair (Assumption 2.2; sets
    across pairs may still hold several features of one camera), and true pairs."""
    n = draw(st.integers(2, 4))
    m = draw(st.lists(st.integers(1, 5), min_size=n, max_size=n))
    rows = []
    for i, j in itertools.combinations(range(n), 2):
        k = draw(st.integers(0, min(m[i], m[j])))
        fi = draw(st.permutations(range(m[i])))[:k]
        fj = draw(st.permutations(range(m[j])))[:k]
        rows += zip([i] * k, fi, [j] * k, fj, strict=True)
    total = sum(m)
    truth = [p for p in draw(st.lists(st.tuples(st.integers(0, total - 1),
                                                st.integers(0, total - 1)), max_size=20))
             if p[0] != p[1]]
    return m, rows, truth


@settings(max_examples=200, deadline=None)
@given(_any_links())
def test_closure_scores_equal_the_enumerated_pairs_of_every_set(case):
    m, rows, truth = case
    cols = list(zip(*rows, strict=True)) if rows else [(), (), (), ()]
    links = Links(*(np.array(c, dtype=np.int64) for c in cols))
    t = np.array(truth, dtype=np.int64).reshape(-1, 2)
    want = _reference(_closure_pairs(m, rows), {frozenset(p) for p in truth})
    got_fast = PairwiseTruth(t, sum(m)).scores(m, links)
    got_listed = pairwise_scores(association_pairs(m, links), t, sum(m))
    assert _close(got_fast, want), (got_fast, want)
    assert _close(got_listed, want), (got_listed, want)


def test_closure_scores_hand_computed():
    # cameras of 2, 1, 1 features (global ids 0, 1 | 2 | 3); links 0:0-1:0, 1:0-2:0,
    # 0:1-2:0 put all four features in one set: 6 implied pairs, 0:1-1:0 (1, 2) and
    # 0:0-2:0 (0, 3) by no link; the 3 true pairs all lie in the set
    links = Links([0, 1, 0], [0, 0, 1], [1, 2, 2], [0, 0, 0])
    truth = np.array([[0, 2], [3, 0], [1, 2]])
    s = PairwiseTruth(truth, 4).scores([2, 1, 1], links)
    assert (s["predicted_pairs"], s["correct_pairs"], s["true_pairs"]) == (6, 3, 3)
    assert (s["precision"], s["recall"]) == (0.5, 1.0)
    assert abs(s["f1"] - 2 / 3) <= 1e-12


def test_a_pair_naming_feature_m_total_is_refused_and_m_total_minus_one_taken():
    # features are 0..m_total - 1: feature 4 of 4 features is past the last one
    with pytest.raises(InputError, match=r"row 0 \[0, 4\] names a feature outside 0..3"):
        pairwise_scores(np.array([[0, 4]]), np.array([[0, 1]]), m_total=4)
    with pytest.raises(InputError, match=r"row 1 \[4, 2\]"):
        PairwiseTruth(np.array([[0, 1], [4, 2]]), 4)
    s = pairwise_scores(np.array([[0, 3]]), np.array([[3, 0]]), m_total=4)
    assert (s["predicted_pairs"], s["correct_pairs"]) == (1, 1)
