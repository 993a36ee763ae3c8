"""The history repair without overturning (``overturn=False``,
pipeline.consistency.engines.online_history): it cuts only the step's new links, and the
association stays conflict-free even when each robot's retired frames of a piece are
summarized as one span (the links joined before the step are joined whatever the spans say)."""

from unittest import mock

import numpy as np
from hypothesis import HealthCheck, given, settings
from online_streams import streams

from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.engines.online import HISTORY, OnlineAssociation


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_steps=10))
def test_without_overturn_only_new_links_are_cut_and_the_association_stays_conflict_free(data):
    window, hold, stream = data
    with mock.patch("pipeline.consistency.engines.online.RUNS_PER_ROBOT", 1):
        oa = OnlineAssociation(window, resolution="paper", hold=hold, overturn=False)
        for t, (frames, links) in enumerate(stream):
            oa.add_step(frames, links)
            assert is_conflict_free(oa.m, oa.kept_links())
            L = oa.links
            by_history = (L.step_cut == t) & (L.reason == HISTORY)
            assert (np.asarray(L.step_added)[by_history] == t).all()
