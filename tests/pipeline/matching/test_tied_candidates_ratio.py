"""Two identical candidates at distance 0 from a descriptor: nothing tells them apart, so its
Lowe ratio is 1 (ambiguous), in ``lowe_ratios`` as in ``mutual_ratio_matches`` and the
brute-force reference of ``test_pairs_reference``. ``lowe_ratios`` gave 0 (0 / 0 floored
to 0 / 1e-6): the most ambiguous COLMAP match of a copied image ranked as the surest."""

import numpy as np

from pipeline.matching.pairs import lowe_ratios, mutual_ratio_matches


def test_a_match_with_an_identical_second_candidate_has_ratio_one():
    d_i = np.array([[1.0, 2.0], [7.0, 1.0]], np.float32)
    d_j = np.array([[1.0, 2.0], [1.0, 2.0], [5.0, 5.0]], np.float32)  # rows 0 and 1 the same
    np.testing.assert_array_equal(lowe_ratios(d_i, d_j, np.array([[0, 0], [0, 1]])), [1.0, 1.0])
    # mutual_ratio_matches rejects the pair as ambiguous even at the loosest threshold
    pairs, _ = mutual_ratio_matches(d_i[:1], d_j, 1.0)
    assert len(pairs) == 0
    # the same descriptor with one copy gone: distance 0 to its only near candidate, ratio 0
    np.testing.assert_allclose(lowe_ratios(d_i, d_j[1:], np.array([[0, 0]])), [0.0], atol=1e-6)
