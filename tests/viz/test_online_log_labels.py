"""Labels of the online recording's frame-pair strips: a pair with one link was labelled
'1 links'."""

import numpy as np

from viz.online_log import _pair_strips


def test_a_pair_with_one_link_says_one_link():
    centres = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    strips, labels = _pair_strips(centres, np.array([0, 0, 1]), np.array([1, 1, 2]))
    assert labels == ["2 links", "1 link"] and len(strips) == 2
    assert _pair_strips(centres, np.array([], int), np.array([], int)) == ([], [])
