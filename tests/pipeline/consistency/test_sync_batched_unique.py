"""The batched sync engine and the cycle support take distinct keys by sorting: NumPy 2.4's
np.unique without return_* hashes, 10-20 times slower on millions of keys, and was most of a
350,000-match clean-h5 run (17 of 25 s)."""

import sys

import numpy as np
from sync_instances import planted_instance
from test_sync_batched import _team

from pipeline.consistency.engines.sync_batched import run_sync_batched

HOT = ("pipeline.consistency.engines.sync_batched", "pipeline.consistency.cycles")


def test_unique_is_numpys():
    from pipeline.consistency.keys import unique

    rng = np.random.default_rng(0)
    for x in (np.zeros(0, np.int64), np.array([5]), rng.integers(0, 50, 1000),
              rng.integers(-10**12, 10**12, 500)):
        np.testing.assert_array_equal(unique(x), np.unique(x))


def test_the_batched_engine_never_hashes(monkeypatch):
    fpc, links, weight = planted_instance(3, 8, 12, 0.9, 0.3, False, "ring2")
    robots, net = _team(fpc, links, weight, "links")
    hashed = []
    numpy_unique = np.unique

    def spy(ar, *args, **kwargs):
        caller = sys._getframe(1).f_globals.get("__name__")
        if caller in HOT and not any(kwargs.get(k) for k in (
                "return_index", "return_inverse", "return_counts")) and not args:
            hashed.append(caller)
        return numpy_unique(ar, *args, **kwargs)

    monkeypatch.setattr(np, "unique", spy)
    res = run_sync_batched(robots, net)
    assert res["rounds"] > 0
    assert hashed == []
