"""The batched ``sync`` engine reports its rounds while it computes them, so that the round
counter of a long run (pipeline.progress.rounds_bar) moves during the stage instead of
jumping to the end once it is over."""

from unittest.mock import patch

from sync_instances import planted_instance
from test_sync_batched import _team

from pipeline.consistency.engines import sync_batched
from pipeline.consistency.engines.sync_batched import run_sync_batched, sync_batched_applies


def test_rounds_are_reported_as_the_boruvka_rounds_are_computed():
    fpc, links, weight = planted_instance(11, 12, 8, 0.9, 0.6, False, "ring2")
    robots, net = _team(fpc, links, weight, "tree")
    assert sync_batched_applies(robots, net)
    seen: list[int] = []
    told_at_flood: list[int] = []  # rounds reported when each max-flood starts
    flood = sync_batched._flood_best

    def spy(*a, **k):
        told_at_flood.append(len(seen))
        return flood(*a, **k)

    with patch.object(sync_batched, "_flood_best", spy), \
            patch.object(sync_batched, "run_sync", side_effect=AssertionError("fell back")):
        res = run_sync_batched(robots, net, on_round=seen.append)
    assert len(told_at_flood) >= 3
    # every flood after the first starts with more rounds told than the one before it
    assert all(b > a for a, b in zip(told_at_flood, told_at_flood[1:], strict=False))
    assert seen == list(range(1, res["rounds"] + 1))  # each round once, in order
