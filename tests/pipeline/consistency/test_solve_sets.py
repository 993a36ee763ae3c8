"""Several sets solved at once (what a root that completes many sets in one round does) give
each set the solution the rule computes on it alone."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.consistency.evidence import solve_set, solve_sets


def _scene_sets(seed: int, n_sets: int, p_unposed: float, tie_weights: bool) -> list[dict]:
    """Up to ``n_sets`` disjoint sets of bundles (gid -> keypoint, neighbour gids, weights, camera,
    projection). Each set: 3-6 cameras around a few 3D points, each feature a point's image
    plus noise, links mostly between views of one point, some wrong; a set is unposed (no
    projection) with probability ``p_unposed``."""
    rng = np.random.default_rng(seed)
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    sets, gid = [], 0
    for _ in range(n_sets):
        n_cam, n_pts = int(rng.integers(3, 7)), int(rng.integers(1, 4))
        X = rng.normal(0, 0.5, (n_pts, 3)) + [0, 0, 6]
        P = []
        for _c in range(n_cam):
            a = rng.normal(0, 0.15, 3)
            R = np.array([[np.cos(a[1]), 0, np.sin(a[1])], [0, 1, 0],
                          [-np.sin(a[1]), 0, np.cos(a[1])]])
            P.append(K @ np.c_[R, rng.normal(0, 0.4, 3)])
        unposed = rng.random() < p_unposed
        feats = []   # (gid, camera, point, keypoint)
        for c in range(n_cam):
            for p in range(n_pts):
                if rng.random() < 0.85:
                    x = P[c] @ np.r_[X[p], 1.0]
                    feats.append((gid, c, p, (x[:2] / x[2] + rng.normal(0, 0.5, 2))
                                  .astype(np.float32)))
                    gid += 1
        links = []
        for u in range(len(feats)):
            for v in range(u + 1, len(feats)):
                fu, fv = feats[u], feats[v]
                if fu[1] == fv[1]:
                    continue
                right = fu[2] == fv[2]
                if (right and rng.random() < 0.7) or (not right and rng.random() < 0.15):
                    w = float(rng.integers(0, 3)) if tie_weights else float(rng.normal(2, 2))
                    links.append((fu[0], fv[0], w))
        if not links:
            continue
        # a set is one component of its links: keep the features the links touch, and only
        # the component of the first link (so the sets are disjoint and connected)
        adj = {}
        for a, b, _ in links:
            adj.setdefault(a, set()).add(b)
            adj.setdefault(b, set()).add(a)
        comp, todo = set(), [links[0][0]]
        while todo:
            g = todo.pop()
            if g not in comp:
                comp.add(g)
                todo.extend(adj[g] - comp)
        by_gid = {f[0]: f for f in feats}
        bundles = {}   # in no particular order, as a root receives them
        for g in rng.permutation(sorted(comp)).tolist():
            mine = [(b if a == g else a, w) for a, b, w in links if g in (a, b)]
            _, c, _, kp = by_gid[g]
            bundles[g] = (kp, np.array([o for o, _ in mine], np.int64),
                          np.array([w for _, w in mine], np.float64), c,
                          None if unposed else P[c])
        sets.append(bundles)
    return [sets[k] for k in rng.permutation(len(sets))]


def _check(sets):
    together = solve_sets(sets)
    assert len(together) == len(sets)
    for bundles, got in zip(sets, together, strict=True):
        want = solve_set(bundles)
        for g, w in zip(got, want, strict=True):
            assert g.dtype == w.dtype and np.array_equal(g, w)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_sets=st.integers(0, 12),
       p_unposed=st.sampled_from([0.0, 0.5, 1.0]), tie_weights=st.booleans())
def test_sets_solved_together_are_solved_as_alone(seed, n_sets, p_unposed, tie_weights):
    _check(_scene_sets(seed, n_sets, p_unposed, tie_weights))


def test_many_posed_scenes_solved_together_are_solved_as_alone():
    """Posed sets whose geometry decides some cuts (a set's features passed in another set's
    order, or its keypoints taken for another's, would change them)."""
    for seed in range(60):
        _check(_scene_sets(seed, 6, 0.25, False))


def test_the_scenes_exercise_the_geometric_test_and_cuts():
    """The generator above is not vacuous: its posed sets cut links, and some cut a link for
    its geometry alone (the same set without projections keeps it)."""
    cut = by_geometry = 0
    for seed in range(30):
        for bundles in _scene_sets(seed, 4, 0.0, False):
            posed = solve_set(bundles)[4]
            unposed = solve_set({g: (*b[:4], None) for g, b in bundles.items()})[4]
            cut += int(posed.sum())
            by_geometry += int((posed & ~unposed).sum())
    assert cut > 0 and by_geometry > 0
