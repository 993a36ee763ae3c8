"""The steps at which ``run-formation --steps N`` runs the batch association for comparison
(pipeline.runs.online.batch_steps_of)."""

import pytest

from pipeline.runs.online import batch_steps_of


@pytest.mark.parametrize("steps,every,want", [
    (6, 2, {1, 3, 5}),          # every second step, counted from the first
    (5, 2, {1, 3, 4}),          # and the last
    (4, 1, {0, 1, 2, 3}),
    (3, 5, {2}),                # fewer steps than ``every``: the last only
    (4, 0, set()),              # 0: no batch run
])
def test_the_batch_runs_every_so_many_steps_and_at_the_last(steps, every, want):
    assert batch_steps_of(steps, every) == want
