"""Confirmed and refuted links of the quality check, hand-counted."""

import numpy as np

from pipeline.evaluation.quality import quality_evidence
from pipeline.types import Links


def test_a_link_without_a_third_camera_is_neither_confirmed_nor_refuted():
    # triangle 0:0-1:0-2:0 (three confirmed links); 0:1-1:1 alone (no third camera: no
    # verdict); 0:2-1:2 whose ends link to two different features of camera 2 (refuted),
    # and those two links, each with one end linked nowhere else (no verdict)
    links = Links([0, 1, 0, 0, 0, 0, 1], [0, 0, 0, 1, 2, 2, 2],
                  [1, 2, 2, 1, 1, 2, 2], [0, 0, 0, 1, 2, 1, 2],
                  quality=np.array([0.9, 0.8, 0.7, 0.5, 0.1, 0.3, 0.4]))
    got = quality_evidence([3, 3, 3], links)
    assert (got["checked"], got["confirmed"], got["refuted"]) == (7, 3, 1)
    assert got["auc"] == 1.0   # every confirmed quality is above the refuted 0.1
