"""The homography truth's missing links compared communication edges as ordered pairs: an
edge given as ``(j, i)`` had none of its true pairs counted missing, a figure better than the
truth. Edges, true pairs and links are now compared as unordered pairs."""

import numpy as np

from pipeline.evaluation.truth import _missing
from pipeline.types import Links

M = np.array([3, 3])        # two cameras of three features: global ids 0-2 and 3-5
TRUE = np.array([[0, 3], [1, 4]])


def test_an_edge_given_from_its_higher_camera_counts_its_missing_pairs():
    none = Links([], [], [], [])
    assert _missing(TRUE, none, np.array([[0, 1]]), M) == 2
    assert _missing(TRUE, none, np.array([[1, 0]]), M) == 2


def test_a_link_stored_from_its_higher_camera_is_found():
    linked = Links([1], [0], [0], [0])   # camera 1 feature 0 - camera 0 feature 0
    assert _missing(TRUE, linked, np.array([[0, 1]]), M) == 1
    assert _missing(TRUE[:, ::-1], linked, np.array([[1, 0]]), M) == 1
