"""The centralized quality merge keeps a link that closes a cycle inside one cluster."""

import numpy as np

from pipeline.consistency.centralized import quality_merge
from pipeline.types import Links


def test_a_link_inside_one_cluster_is_kept_and_a_second_feature_of_a_camera_cut():
    # triangle 0:0-1:0-2:0 (best qualities), then 2:0-3:0 and 0:1-3:0 (worst), which brings
    # a second feature of camera 0 into the set: the triangle's third link joins two
    # features already in one cluster (kept), the last one would join camera 0 twice (cut)
    links = Links([0, 1, 0, 2, 0], [0, 0, 0, 0, 1], [1, 2, 2, 3, 3], [0, 0, 0, 0, 0],
                  quality=np.array([0.9, 0.8, 0.7, 0.6, 0.1]))
    assert quality_merge([2, 1, 1, 1], links).tolist() == [True, True, True, True, False]
