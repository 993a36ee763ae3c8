"""Small sets solved at their roots (pipeline.consistency.roots): the robots' protocol decides
as the evidence rule's flood does, and the online stage's batched gathering as the robots."""

import numpy as np
from consistency_graphs import instances
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from pipeline.consistency import resolve_conflicts

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _poses(fpc, seed: int):
    rng = np.random.default_rng(seed)
    keypoints = [rng.uniform(0, 100, size=(m, 2)).astype(np.float32) for m in fpc]
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    return keypoints, [K @ np.c_[np.eye(3), rng.normal(0, 0.1, 3) + [0, 0, 5]] for _ in fpc]


@SETTINGS
@given(inst=instances(max_n=7, max_feat=5), budget=st.sampled_from([None, 3, 6]),
       posed=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_the_conflictive_sets_solved_at_their_roots_are_cut_as_the_rules_flood_cuts(
        inst, budget, posed, seed):
    fpc, edges, links = inst
    kp, P = _poses(fpc, seed) if posed else (None, None)
    kw = dict(resolution="evidence", bundle_budget=budget, keypoints=kp, projections=P)
    flood = resolve_conflicts(fpc, edges, links, **kw)
    roots = resolve_conflicts(fpc, edges, links, gather_conflictive=True, **kw)
    np.testing.assert_array_equal(roots.deleted, flood.deleted)
    np.testing.assert_array_equal(roots.case == "", flood.case == "")
    event(f"cut {int(roots.deleted.sum())}")


def test_a_sets_root_is_one_member_whatever_the_order_and_rarely_its_smallest():
    """Every robot of a set names the same root from its member list, in any order; over
    sets of consecutive ids the root is the smallest in about one set of ten (the smallest id
    as root put every set of a step on the robot of the first frame)."""
    import numpy as np

    from pipeline.consistency.roots import root_of

    rng = np.random.default_rng(0)
    smallest = 0
    for k in range(200):
        members = np.arange(10 * k, 10 * k + 10)
        r = root_of(members)
        assert r in members and root_of(rng.permutation(members)) == r
        smallest += r == members.min()
    assert smallest < 60, smallest
