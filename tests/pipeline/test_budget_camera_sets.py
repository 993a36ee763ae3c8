"""The memory guard counts the ``sync`` rule's camera bit sets, which grow with the linked
features times the cameras: on a chain of many cameras they, not the links, make the peak."""

import numpy as np
import pytest

from pipeline.budget import BYTES_PER_SYNC_LINK, MemoryBudget, check_detection_memory
from pipeline.consistency.rules import get_rule
from pipeline.errors import InputError
from pipeline.types import Links

# 6,400 cameras, camera 2k linked to camera 2k + 1 by one pair of features: 3,200 links,
# 6,400 linked features, a camera set of 100 words
N = 6400
CAM = np.arange(0, N, 2)
LINKS = Links(CAM, np.zeros(CAM.size, np.int64), CAM + 1, np.zeros(CAM.size, np.int64))
FPC = np.ones(N, np.int64)


def test_sync_counts_a_set_of_every_camera_per_linked_feature():
    sync = get_rule("sync")
    links_only = len(LINKS) * BYTES_PER_SYNC_LINK  # 3.8 MB
    sets = N * 2 * (8 + 8 * 100)  # 10.3 MB
    budget = MemoryBudget(1.0)
    check_detection_memory(FPC, LINKS, budget, detection=sync.detection,
                           camera_sets=sync.camera_sets)
    assert budget.total == sets > links_only
    with pytest.raises(InputError, match="sets of cameras.*6400 features linked.*6400 cameras"):
        check_detection_memory(FPC, LINKS, (links_only * 2) / 1e9, detection=sync.detection,
                               camera_sets=sync.camera_sets)


def test_a_rule_without_camera_sets_counts_the_links_only():
    labels = get_rule("paper-labels")
    assert not labels.camera_sets
    budget = MemoryBudget(1.0)
    check_detection_memory(FPC, LINKS, budget, detection=labels.detection,
                           camera_sets=labels.camera_sets)
    assert budget.total == len(LINKS) * BYTES_PER_SYNC_LINK
