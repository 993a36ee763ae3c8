"""A lone candidate (one descriptor on the other side) has no second neighbour, so the ratio
test cannot reject it: every matcher of :mod:`pipeline.matching` gives it the ratio 0.
``lowe_ratios`` gave it 1 (the worst ratio, quality 0) while ``mutual_ratio_matches`` gave
the same match 0 (the best): a COLMAP match and an OpenCV match of one pair of images were
weighed at the two ends of the scale."""

import numpy as np

from pipeline.matching.landmarks import hungarian_match
from pipeline.matching.pairs import lowe_ratios, mutual_ratio_matches


def test_a_lone_candidate_has_ratio_zero_in_every_matcher():
    d_i = np.array([[0.0, 0.0], [4.0, 1.0], [9.0, 9.0]], np.float32)
    d_j = np.array([[3.0, 4.0]], np.float32)  # one descriptor: no second neighbour
    pairs, ratio = mutual_ratio_matches(d_j, d_i, 0.8)
    # d_j's one descriptor has three in d_i (nearest 3.16, second 5: ratio 0.63); each of
    # those has a lone candidate
    np.testing.assert_array_equal(pairs, [[0, 1]])
    lone = lowe_ratios(d_i, d_j, np.array([[0, 0], [1, 0], [2, 0]]))
    np.testing.assert_array_equal(lone, [0.0, 0.0, 0.0])
    # both directions of lowe_ratios agree with the link ratio of mutual_ratio_matches
    back = lowe_ratios(d_j, d_i, pairs)
    np.testing.assert_allclose(np.maximum(back, lowe_ratios(d_i, d_j, pairs[:, ::-1])), ratio,
                               rtol=1e-5)
    # the landmarks' assignment: one landmark each side, no alternative, ratio 0
    _, _, rho = hungarian_match(np.array([[0.7]]), ratio=None)
    np.testing.assert_array_equal(rho, [0.0])


def test_a_lone_candidate_passes_any_threshold_in_both_matchers():
    d_i = np.array([[1.0, 2.0]], np.float32)
    d_j = np.array([[1.5, 2.5]], np.float32)
    pairs, ratio = mutual_ratio_matches(d_i, d_j, 1e-6)
    np.testing.assert_array_equal(pairs, [[0, 0]])
    np.testing.assert_array_equal(lowe_ratios(d_i, d_j, pairs), ratio)
