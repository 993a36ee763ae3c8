"""The memory guard of --baselines counts the dense eigenproblem of a large component whose
universe needs a quarter of its features or more: three cameras whose links chain 33,675
features into one set passed a 2 GB limit and ran out of memory past 5 GB."""

import numpy as np

from pipeline import budget
from pipeline.budget import baselines_bytes
from pipeline.types import Links


def _three_cameras(m, seed=0):
    """Three cameras of ``m`` features, each pair matched by a random permutation: one set
    chaining most features, ``m`` of one camera in it."""
    rng = np.random.default_rng(seed)
    ci, fi, cj, fj = [], [], [], []
    for i, j in ((0, 1), (1, 2), (0, 2)):
        ci.append(np.full(m, i))
        fi.append(np.arange(m))
        cj.append(np.full(m, j))
        fj.append(rng.permutation(m))
    return [m, m, m], Links(*(np.concatenate(x) for x in (ci, fi, cj, fj)))


def test_a_set_that_must_be_solved_densely_is_counted_whole(monkeypatch):
    monkeypatch.setattr(budget, "BASELINE_DENSE_FEATURES", 50)
    fpc, links = _three_cameras(100)
    dense = budget.spectral_dense_features(fpc, links)
    assert dense > 150  # the giant set, not the 50 of the cap
    assert baselines_bytes(fpc, links) >= 3 * 8 * dense * dense


def test_a_long_chain_of_one_feature_per_camera_keeps_the_cap(monkeypatch):
    monkeypatch.setattr(budget, "BASELINE_DENSE_FEATURES", 50)
    n = 400  # one set of 400 features, one per camera: 1 universe point, solved by ARPACK
    cams = np.arange(n - 1)
    links = Links(cams, np.zeros(n - 1, np.int64), cams + 1, np.zeros(n - 1, np.int64))
    assert budget.spectral_dense_features([1] * n, links) == 50
