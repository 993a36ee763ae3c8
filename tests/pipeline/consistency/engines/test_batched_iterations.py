"""The batched engines against the per-robot engine over several iterations of Prop. 4.5: a
later resolution starts with the components of the earlier ones already assigned."""

from unittest.mock import patch

import numpy as np
import pytest
from consistency_graphs import random_instance
from test_batched import _no_fallback, _same_result

from pipeline.consistency import resolve_conflicts
from pipeline.consistency.engines import batched_resolution


@pytest.mark.parametrize("n, max_feat, p_edge, p_link, seed",
                         [(8, 10, 0.5, 0.8, 158), (10, 12, 0.4, 0.8, 50), (10, 12, 0.4, 0.8, 97)])
def test_batched_equals_per_robot_over_several_iterations(n, max_feat, p_edge, p_link, seed,
                                                          tmp_path):
    fpc, edges, links = random_instance(np.random.default_rng(seed), n, max_feat, p_edge, p_link)
    per_robot = resolve_conflicts(fpc, edges, links, resolution="paper", engine="per-robot")
    assert per_robot.stats["iterations"] >= 2
    with patch.object(batched_resolution, "_run_stepped", _no_fallback):
        in_batch = resolve_conflicts(fpc, edges, links, resolution="paper", engine="batched")
    _same_result(per_robot, in_batch, tmp_path)
