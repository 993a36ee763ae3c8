"""The quality merge baseline decides by the links, not by the rows' order of their file."""

import itertools

import numpy as np

from pipeline.consistency.centralized import quality_merge
from pipeline.types import Links


def test_tied_links_in_another_row_order_are_merged_alike():
    # the chain 0:0 - 1:0 - 2:0 - 0:1 joins two features of camera 0; every quality tied
    ci, fi, cj, fj = np.array([0, 1, 0]), np.array([0, 0, 1]), np.array([1, 2, 2]), \
        np.array([0, 0, 0])
    m = [2, 1, 1]
    first = quality_merge(m, Links(ci, fi, cj, fj, np.ones(3)))
    assert first.tolist() == [True, False, True]
    for p in itertools.permutations(range(3)):
        p = np.array(p)
        again = quality_merge(m, Links(ci[p], fi[p], cj[p], fj[p], np.ones(3)))
        assert again.tolist() == first[p].tolist()
