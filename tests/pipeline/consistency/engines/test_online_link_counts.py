"""The online record's count of kept links per feature (pipeline.consistency.engines.online),
which decides which retiring features join a retired piece."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from online_streams import streams

from pipeline.consistency.engines.online import OnlineAssociation


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_steps=5))
def test_each_feature_counts_its_kept_links_after_every_step(data):
    """After every step (cuts by the rule, the weighing and the history repair included)
    ``degree`` is each feature's number of kept links."""
    window, hold, stream = data
    oa = OnlineAssociation(window, resolution="paper", hold=hold)
    for frames, links in stream:
        oa.add_step(frames, links)
        L = oa.links
        a, b = oa.offset[L.ci] + L.fi, oa.offset[L.cj] + L.fj
        n = len(oa.label)
        want = np.bincount(a[L.kept], minlength=n) + np.bincount(b[L.kept], minlength=n)
        np.testing.assert_array_equal(oa.degree, want)
