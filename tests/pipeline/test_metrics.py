import numpy as np

from pipeline.metrics import association_pairs, pairwise_scores
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
