"""The quality check's draw of links (beyond its caps) does not follow the rows' order."""

import numpy as np
import pytest
from test_quality_evidence import _ring2

from pipeline.evaluation.quality import quality_evidence
from pipeline.types import Links


@pytest.mark.parametrize("caps", [{"max_checked": 150}, {"max_entries": 1500}])
def test_the_same_links_in_another_row_order_with_ends_swapped_give_the_same_check(caps):
    m, ci, fi, cj, fj, good = _ring2(0)
    rng = np.random.default_rng(1)
    q = np.where(good, rng.uniform(0.4, 0.9, good.size), rng.uniform(0.1, 0.6, good.size))
    first = quality_evidence(m, Links(ci, fi, cj, fj, q), **caps)
    assert first["checked"] < good.size  # the draw is in play
    p = rng.permutation(good.size)
    swap = rng.random(good.size) < 0.5
    a_c, a_f = np.where(swap, cj, ci)[p], np.where(swap, fj, fi)[p]
    b_c, b_f = np.where(swap, ci, cj)[p], np.where(swap, fi, fj)[p]
    assert quality_evidence(m, Links(a_c, a_f, b_c, b_f, q[p]), **caps) == first
