"""Link weights of the spectral rules: a pair listed twice counts once with its larger weight,
and a link of weight 0 is no link."""

import numpy as np

from pipeline.consistency.spectral import association_matrix, spectral_sync
from pipeline.types import Links


def test_a_pair_listed_twice_counts_once_with_its_larger_weight():
    # the pair (camera 0 feature 0, camera 1 feature 0), once from each side
    W = association_matrix([1, 1], Links([0, 1], [0, 0], [1, 0], [0, 0]), np.array([0.3, 0.8]))
    np.testing.assert_array_equal(W.toarray(), [[1.0, 0.8], [0.8, 1.0]])


def test_a_link_of_weight_zero_is_no_link():
    # cameras 0 (two features), 1, 2; links (0,0)-(1,0), (0,1)-(2,0), (1,0)-(2,0)
    links = Links([0, 0, 1], [0, 1, 0], [1, 2, 2], [0, 0, 0])
    weight = np.array([1.0, 0.0, 1.0])
    without = Links([0, 1], [0, 0], [1, 2], [0, 0])
    np.testing.assert_array_equal(spectral_sync([2, 1, 1], links, weight=weight),
                                  spectral_sync([2, 1, 1], without, weight=np.array([1.0, 1.0])))
