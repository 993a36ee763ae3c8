"""A link the evidence rule's stage cuts in a large set (by the merge of its phase 3) is the
rule's cut: its case is ``evidence``, in either engine."""

import numpy as np
import pytest

from pipeline.consistency import resolve_conflicts
from pipeline.types import Links


@pytest.mark.parametrize("engine", ["per-robot", "batched"])
def test_a_cut_of_the_merge_on_a_large_set_is_the_rules(engine):
    # 0:0 - 1:0 - 2:0 - 0:1: camera 0 twice in a set of four features, above B = 1
    links = Links([0, 1, 0], [0, 0, 1], [1, 2, 2], [0, 0, 0], [0.9, 0.8, 0.2])
    res = resolve_conflicts(np.array([2, 1, 1]), None, links, resolution="evidence",
                            bundle_budget=1, engine=engine)
    assert res.stats["large_sets"] == 1
    assert res.deleted.tolist() == [False, False, True]  # the weakest link
    assert res.case.tolist() == ["", "", "evidence"]
