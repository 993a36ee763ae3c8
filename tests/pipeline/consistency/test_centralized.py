"""Centralized references: union-find detection and the baselines real SfM tools use."""

import numpy as np
from consistency_graphs import instances
from hypothesis import HealthCheck, given, settings

from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import (
    drop_conflictive_sets,
    is_conflict_free,
    keep_first_per_image,
    quality_merge,
    union_find_conflicts,
)
from pipeline.types import Links

FPC = [1, 1, 1, 2]
FIG1 = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0], [0.9, 0.2, 0.8, 0.7])


def test_union_find_on_fig1():
    labels, conflictive = union_find_conflicts(FPC, FIG1)
    assert np.unique(labels).size == 1 and conflictive.all()


def test_baselines_on_fig1_by_hand():
    assert drop_conflictive_sets(FPC, FIG1).tolist() == [False] * 4
    # Theia-style: D keeps f1^D (lowest id), so the link A-f2^D goes
    assert keep_first_per_image(FPC, FIG1).tolist() == [False, True, True, True]
    # Kruskal by quality 0.9, 0.8, 0.7, 0.2: A-f2^D, B-C, C-f1^D, then A-B would join D twice
    assert quality_merge(FPC, FIG1).tolist() == [True, False, True, True]


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances())
def test_every_baseline_is_conflict_free(inst):
    fpc, edges, links = inst
    drop = drop_conflictive_sets(fpc, links)
    for kept in (drop, keep_first_per_image(fpc, links), quality_merge(fpc, links)):
        assert kept.shape == (len(links),)
        assert is_conflict_free(fpc, links.subset(kept))
    # the quality merge and the distributed stage only cut inside conflictive sets
    assert (quality_merge(fpc, links) >= drop).all()
    assert (~resolve_conflicts(fpc, edges, links, resolution="paper").deleted >= drop).all()


def test_baselines_refuse_counts_that_are_not_whole_numbers():
    # 2.5 features was read as 2: the baselines judged other counts than those given
    import pytest

    from pipeline.consistency.centralized import BASELINES
    from pipeline.errors import InputError

    for fn in [is_conflict_free, *BASELINES.values()]:
        with pytest.raises(InputError, match=r"features_per_camera\[3\] = 2.5"):
            fn([1, 1, 1, 2.5], FIG1)
