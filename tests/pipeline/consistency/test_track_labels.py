"""Each robot names the tracks of its features from its own knowledge (detection rows and
Alg. 1 components); the names partition the features exactly like a union-find of the kept
links, the same name at every robot of a track."""

import numpy as np
from consistency_graphs import instances
from hypothesis import given, settings

from pipeline.consistency import resolve_conflicts
from pipeline.fusion.landmarks import tracks_of
from pipeline.transport.simulated import NetworkOptions


def _same_partition(a, b):
    on = a >= 0
    if not np.array_equal(on, b >= 0):
        return False
    pairs = set(zip(a[on].tolist(), b[on].tolist(), strict=True))
    return len(pairs) == len(set(a[on].tolist())) == len(set(b[on].tolist()))


@settings(max_examples=60, deadline=None)
@given(instances())
def test_robot_track_names_are_the_sets_of_the_kept_links(inst):
    fpc, edges, links = inst
    res = resolve_conflicts(fpc, None, links, resolution="paper")
    track_of, _ = tracks_of(fpc, res.kept())
    assert _same_partition(track_of, res.track_label)


@settings(max_examples=20, deadline=None)
@given(instances())
def test_robot_track_names_under_loss(inst):
    fpc, edges, links = inst
    res = resolve_conflicts(fpc, None, links, NetworkOptions(drop_probability=0.3, seed=1),
                            resolution="paper")
    track_of, _ = tracks_of(fpc, res.kept())
    assert _same_partition(track_of, res.track_label)
