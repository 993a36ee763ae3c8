"""Pair-level loop check: one corrupted relative rotation found on a synthetic view graph,
nothing found where every loop closes, a ring without triangles left alone, bad input."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from pipeline.errors import InputError
from pipeline.matching.loops import cycle_error_deg, loop_check


def _view_graph(n, pairs, seed, noise_deg=1.0):
    """True absolute rotations; each pair's ``R_ij = R_j R_iᵀ`` with a little noise."""
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=seed).as_matrix()
    rel = np.stack([R[j] @ R[i].T for i, j in pairs])
    noise = Rotation.from_rotvec(rng.normal(size=(len(pairs), 3))
                                 * np.deg2rad(noise_deg) / np.sqrt(3)).as_matrix()
    return noise @ rel


def _corrupt(R, angle_deg, seed):
    axis = np.random.default_rng(seed).normal(size=3)
    axis /= np.linalg.norm(axis)
    return Rotation.from_rotvec(axis * np.deg2rad(angle_deg)).as_matrix() @ R


def test_cycle_error_is_the_leftover_angle():
    Rz = Rotation.from_euler("z", [[30], [50], [80]], degrees=True).as_matrix()
    # R_ij = 30°, R_jk = 50°, R_ik = 80° about one axis: the triangle closes
    assert cycle_error_deg(Rz[0], Rz[1], Rz[2]) == pytest.approx(0.0, abs=1e-6)
    assert cycle_error_deg(Rz[0], Rz[1], Rz[1]) == pytest.approx(30.0, abs=1e-6)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(5, 9), seed=st.integers(0, 10**6), data=st.data())
def test_one_corrupted_pair_is_found(n, seed, data):
    """Complete view graph, one pair's rotation turned by 3–12 tolerances: exactly that pair
    fails its loops, when it is the lightest of the pairs it shares an image with (a wrong
    two-view geometry between two images of repeated structure has few inliers)."""
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
    R = _view_graph(n, pairs, seed)
    bad = data.draw(st.integers(0, len(pairs) - 1))
    R[bad] = _corrupt(R[bad], data.draw(st.floats(45.0, 179.0)), seed)
    rng = np.random.default_rng(seed + 1)
    w = rng.integers(50, 500, size=len(pairs)).astype(float)
    touching = np.isin(pairs, pairs[bad]).any(axis=1)
    w[bad] = w[touching].min() - 1
    res = loop_check(n, pairs, R, w, tol_deg=15.0)
    assert np.flatnonzero(res.inconsistent).tolist() == [bad]
    assert res.inconsistent_triangles[bad] > 0 and res.consistent_triangles[bad] == 0
    assert res.summary()["pairs_dropped"] == 1


def test_consistent_graph_keeps_every_pair():
    n = 7
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n) if j - i <= 3])
    R = _view_graph(n, pairs, 3)
    res = loop_check(n, pairs, R, np.arange(len(pairs), dtype=float))
    assert not res.inconsistent.any()
    assert (res.consistent_triangles > 0).all()


@pytest.mark.parametrize("bad", [0, 1, 2, 3])
def test_a_square_blames_its_lightest_pair(bad):
    """A ring of four: no triangle, one square; when it does not close, only its lightest
    pair is dropped (the corrupted one, lightest here)."""
    pairs = np.array([(0, 1), (1, 2), (2, 3), (0, 3)])
    R = _view_graph(4, pairs, 5)
    R[bad] = _corrupt(R[bad], 90.0, 5)
    w = np.full(4, 100.0)
    w[bad] = 20.0
    res = loop_check(4, pairs, R, w)
    assert np.flatnonzero(res.inconsistent).tolist() == [bad]
    # each image sends each neighbour its 2 pairs: 4 edges x (2 + 2)
    assert res.two_hop_entries == 16


def test_pairs_on_no_cycle_are_not_judged():
    """The same ring with one pair without a rotation: no cycle left, nothing dropped, the
    pair without a rotation kept unjudged."""
    pairs = np.array([(0, 1), (1, 2), (2, 3), (0, 3)])
    R = _view_graph(4, pairs, 5)
    R[1] = _corrupt(R[1], 90.0, 5)
    R[2] = np.nan
    res = loop_check(4, pairs, R, np.ones(4))
    assert not res.inconsistent.any()
    assert res.judged.tolist() == [True, True, False, True]
    assert res.summary()["pairs_without_triangle"] == 3


@pytest.mark.parametrize("tol", [0.0, -5.0, 180.0, float("nan"), float("inf")])
def test_bad_tolerance_is_named(tol):
    pairs = np.array([(0, 1), (1, 2), (0, 2)])
    with pytest.raises(InputError, match="loop tolerance"):
        loop_check(3, pairs, _view_graph(3, pairs, 0), np.ones(3), tol_deg=tol)


@pytest.mark.parametrize("pairs, what", [([(1, 0)], "i < j"), ([(0, 3)], "i < j"),
                                          ([(0, 1), (0, 1)], "listed twice")])
def test_bad_pairs_are_named(pairs, what):
    pairs = np.array(pairs)
    R = np.broadcast_to(np.eye(3), (len(pairs), 3, 3))
    with pytest.raises(InputError, match=what):
        loop_check(3, pairs, R, np.ones(len(pairs)))
