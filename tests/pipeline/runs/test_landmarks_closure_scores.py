"""run-landmarks scores the closure of the links per association set: listing the pairs a
set implies (k (k - 1) / 2 of them) ran a 200-frame input out of memory once noisy links
chained its features into one set."""

import tracemalloc

import numpy as np

from pipeline.evaluation.metrics import association_pairs, pairwise_scores
from pipeline.runs.landmarks import _scores, true_landmark_pairs
from pipeline.types import Links


def _chain(n):
    """``n`` images of one landmark each, linked in a chain: one set of ``n`` features."""
    cams = np.arange(n - 1)
    return [1] * n, Links(cams, np.zeros(n - 1, np.int64), cams + 1, np.zeros(n - 1, np.int64))


def test_scores_are_those_of_the_listed_pairs():
    m = [3, 3, 3, 3]
    links = Links([0, 0, 1, 2], [0, 1, 0, 2], [1, 2, 3, 3], [0, 2, 1, 2])
    tp = true_landmark_pairs(m)
    assert _scores(m, links, tp) == pairwise_scores(association_pairs(m, links), tp, 12)


def test_one_set_of_thousands_of_features_is_scored_without_listing_its_pairs():
    m, links = _chain(3000)  # 4.5 million implied pairs
    # ten true pairs, image 0's with images 1..10: the first rows of the truth of all 3000
    # images, which are those of the first 11 (listing all 4.5 million took ~40 s)
    tp = true_landmark_pairs(m[:11], [np.zeros(1, np.int64)] * 11)[:10]
    tracemalloc.start()
    try:
        s = _scores(m, links, tp)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert s["predicted_pairs"] == 3000 * 2999 // 2 and s["correct_pairs"] == 10
    assert peak < 5e6, peak
