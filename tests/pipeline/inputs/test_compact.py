"""Compact ids give the same cuts as the ids as given (pipeline.inputs.compact)."""

import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings

from pipeline.consistency import resolve_conflicts
from pipeline.faults import FaultConfig, fault_report
from pipeline.inputs.compact import compact_ids, fault_section_in_ids, faults_in_layout
from pipeline.types import Links

sys.path.insert(0, str(Path(__file__).parents[1] / "consistency"))
from consistency_graphs import instances  # noqa: E402


def _spread(links: Links, edges):
    """The same graph with sparse ids: cameras 3c + 1, features 7r + 2 (orders kept)."""
    sp = Links(3 * links.cam_i + 1, 7 * links.feat_i + 2, 3 * links.cam_j + 1,
               7 * links.feat_j + 2, links.quality)
    return sp, 3 * np.asarray(edges).reshape(-1, 2) + 1


def _same(a, b):
    for key in ("deleted", "reason", "round", "case", "iteration"):
        assert np.array_equal(getattr(a, key), getattr(b, key)), key


@settings(max_examples=40, deadline=None)
@given(instances())
def test_compacting_sparse_ids_changes_no_cut(inst):
    _, edges, links = inst
    links, edges = _spread(links, edges)
    dense, compact = (compact_ids(links, edges, force=f) for f in (False, True))
    assert compact.compacted and not dense.compacted
    assert compact.features_per_camera.sum() <= 2 * len(links)
    a = resolve_conflicts(dense.features_per_camera, dense.edges, dense.links, resolution="paper")
    b = resolve_conflicts(compact.features_per_camera, compact.edges, compact.links,
                          resolution="paper")
    _same(a, b)


@settings(max_examples=15, deadline=None)
@given(instances(max_n=5))
def test_crashes_are_renumbered_and_reported_in_original_ids(inst):
    _, edges, links = inst
    links, edges = _spread(links, edges)
    dense, compact = (compact_ids(links, edges, force=f) for f in (False, True))
    crash = ((int(links.cam_j[0]), 3),) if len(links) else ()
    faults = FaultConfig(drop_prob=0.2, crash=crash, seed=1)
    reports = []
    for ids in (dense, compact):
        f = faults_in_layout(faults, ids)
        opts = f.network_options(ids.edges, ids.features_per_camera.size)
        res = resolve_conflicts(ids.features_per_camera, ids.edges, ids.links, opts,
                                resolution="paper")
        reports.append((res, fault_section_in_ids(fault_report(f, res), ids)))
    _same(reports[0][0], reports[1][0])
    assert reports[0][1] == reports[1][1]


def test_one_huge_id_costs_nothing():
    links = Links([0], [0], [2147483646], [100000000])
    ids = compact_ids(links)
    assert ids.compacted and ids.features_per_camera.tolist() == [1, 1]
    assert ids.cameras.tolist() == [0, 2147483646]


def test_ordinary_ids_are_left_as_given():
    links = Links([0, 1], [5, 3], [1, 2], [3, 9])
    ids = compact_ids(links)
    assert not ids.compacted and ids.links is links
    assert ids.features_per_camera.tolist() == [6, 4, 10]
