"""The history check run by the stage's robots (pipeline.consistency.engines.history_run):
the same cuts, reasons and names as the online record's own check, for every rule."""

import pytest
from hypothesis import HealthCheck, event, given, settings
from online_streams import posed_streams, streams

from pipeline.consistency.engines.online import OnlineAssociation


def _both(window, hold, stream, resolution):
    runs = []
    for robots in (True, False):
        oa = OnlineAssociation(window, resolution=resolution, hold=hold, robots_check=robots)
        runs.append((oa, [oa.add_step(frames, links) for frames, links in stream]))
    return runs


@pytest.mark.parametrize("resolution", ["paper", "evidence", "sync"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_robots=5, max_steps=8, max_m=5))
def test_the_robots_check_cuts_and_names_as_the_record(resolution, data):
    """Every step: the same links kept, cut with the same reason at the same step, and the
    same set names afterwards (the robots' cuts are applied, then every set renamed)."""
    window, hold, stream = data
    (a, ra), (b, rb) = _both(window, hold, stream, resolution)
    for name in ("kept", "reason", "step_cut"):
        assert getattr(a.links, name).tolist() == getattr(b.links, name).tolist(), name
    assert a.label.tolist() == b.label.tolist()
    assert [r["cut_history"] for r in ra] == [r["cut_history"] for r in rb]
    assert a.is_conflict_free()
    event(f"history cuts {sum(r['cut_history'] for r in ra) > 0}")


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=posed_streams(max_robots=4, max_steps=6))
def test_the_robots_check_after_the_weighing_cuts_as_the_record(data):
    """With poses the evidence rule's weighing cuts too (its robots at the roots): the check
    sees the links they kept, as the record's does."""
    window, hold, stream = data
    (a, _), (b, _) = _both(window, hold, stream, "evidence")
    for name in ("kept", "reason", "step_cut"):
        assert getattr(a.links, name).tolist() == getattr(b.links, name).tolist(), name
