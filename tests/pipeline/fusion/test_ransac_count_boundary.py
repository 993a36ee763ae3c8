"""``K`` of RANSAC is the smallest count that reaches the success probability, also where
``log(1 − p_s) / log(1 − p_in^c)`` is a whole number up to rounding."""

import pytest

from pipeline.fusion.consensus import ransac_hypotheses, ransac_success


@pytest.mark.parametrize(("p_in", "c", "success", "k"), [
    (0.9, 1, 0.99, 2),     # 1 − 0.1² = 0.99 exactly
    (0.9, 1, 0.999, 3),    # 1 − 0.1³
    (0.5, 1, 0.75, 2),     # 1 − 0.5²
    (0.5, 2, 0.4375, 2),   # 1 − 0.75²
])
def test_a_whole_ratio_gives_that_count_not_one_more(p_in, c, success, k):
    assert ransac_hypotheses(p_in, c, success) == k
    # k reaches the probability (to rounding), k − 1 does not
    assert ransac_success(p_in, c, k) == pytest.approx(success, rel=0, abs=1e-12)
    assert ransac_success(p_in, c, k - 1) < success - 1e-6
