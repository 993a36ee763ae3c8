"""Formations: the documented communication graphs, parametric graphs, bad input."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components

import data_synth
from data_synth.formations import FIG4_EDGES, GRAPH_KINDS, graph_edges, robot_poses
from pipeline.errors import InputError

SMALL = (64, 48)


def n_components(edges, n):
    e = np.asarray(edges).reshape(-1, 2)
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(A, directed=False)[0]


def test_fig4_edges_as_documented():
    ring = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 5)]
    assert sorted(FIG4_EDGES["a"]) == sorted(ring)
    assert sorted(FIG4_EDGES["b"]) == sorted(ring + [(0, 2), (3, 5)])
    assert sorted(FIG4_EDGES["c"]) == sorted(ring + [(0, 2), (1, 3), (2, 4), (3, 5), (0, 4), (1, 5)])
    assert len(FIG4_EDGES["d"]) == 15
    # cycle rank E - n + 1 grows from (a) to (d): few cycles ... complete
    assert [len(FIG4_EDGES[k]) - 6 + 1 for k in "abcd"] == [1, 3, 7, 10]


@pytest.mark.parametrize("name", ["a", "b", "c", "d"])
def test_rendered_formations_carry_their_graph(name):
    f = data_synth.render(name, seed=0, size=SMALL)
    assert f.name == name and len(f.views) == 6
    e = f.comm_edges
    assert e.dtype == np.int64 and e.shape[1] == 2 and (e[:, 0] < e[:, 1]).all()
    assert sorted(map(tuple, e.tolist())) == sorted(FIG4_EDGES[name])
    assert n_components(e, 6) == 1
    # the rules for other n give the same edges at n = 6
    kind = data_synth.FORMATIONS[name]
    assert sorted(map(tuple, graph_edges(kind, 6).tolist())) == sorted(FIG4_EDGES[name])


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 14), kind=st.sampled_from(GRAPH_KINDS + ("ring+triangles",)),
       seed=st.integers(0, 1000))
def test_parametric_graphs_connected_and_simple(n, kind, seed):
    centres, _ = robot_poses(n, seed)
    e = graph_edges(kind, n, centres, seed)
    assert (e[:, 0] < e[:, 1]).all() and e.min() >= 0 and e.max() < n
    assert len(np.unique(e[:, 0] * n + e[:, 1])) == len(e)
    assert n_components(e, n) == 1
    expected = {"line": n - 1, "ring": n if n > 2 else 1, "complete": n * (n - 1) // 2}
    if kind in expected:
        assert len(e) == expected[kind]
    if kind == "ring2" and n >= 5:
        assert len(e) == 2 * n


def test_parametric_render():
    f = data_synth.render("d", seed=1, size=SMALL, n_robots=4, graph="line")
    assert f.name == "line-n4" and len(f.views) == 4
    assert f.comm_edges.tolist() == [[0, 1], [1, 2], [2, 3]]
    assert f.neighbours(1).tolist() == [0, 2]
    g = data_synth.render("geometric", seed=1, size=SMALL, n_robots=5)
    assert n_components(g.comm_edges, 5) == 1


@pytest.mark.parametrize("kwargs, message", [
    (dict(formation="e"), "unknown formation 'e'.*a, b, c, d"),
    (dict(formation="d", graph="star"), "unknown graph kind 'star'.*line, ring"),
    (dict(n_robots=1), "n_robots must be an integer >= 2, got 1"),
    (dict(n_robots=2.5), "n_robots"),
    (dict(size=(32, 24)), "32x24 is too small.*64x48"),
    (dict(size="big"), "size must be"),
    (dict(size=(161.7, 97.2)), r"whole pixels, got \(161.7, 97.2\)"),
    (dict(size=(True, 97)), r"whole pixels, got \(True, 97\)"),
    # refused before any allocation (the renderer would ask for 112 GiB here)
    (dict(size=(100000, 100000)), "100000x100000 is too large"),
    (dict(size=(8193, 64)), "8193x64 is too large"),
    (dict(size=(4097, 4097)), "4097x4097 is too large"),
    (dict(seed=-1), "seed must be an integer >= 0"),
    # refused before any allocation (10**9 robots exhausted the memory in the poses)
    (dict(n_robots=10**9, size=SMALL), "n_robots 1000000000: at most 1000 robots"),
])
def test_bad_input(kwargs, message):
    with pytest.raises(InputError, match=message):
        data_synth.render(**kwargs)


def test_the_largest_team_is_accepted_and_one_more_refused_in_every_entry_point():
    from data_synth.motion import render_motion
    from pipeline.validate import MAX_ROBOTS

    assert len(data_synth.formation_edges("ring", n_robots=MAX_ROBOTS)) == MAX_ROBOTS
    for call in (lambda: data_synth.formation_edges("ring", n_robots=MAX_ROBOTS + 1),
                 lambda: data_synth.render_robot(0, "ring", n_robots=MAX_ROBOTS + 1, size=SMALL),
                 lambda: render_motion("ring", n_robots=MAX_ROBOTS + 1, steps=1, size=SMALL)):
        with pytest.raises(InputError, match=f"at most {MAX_ROBOTS} robots"):
            call()


def test_a_numpy_seed_renders_what_the_same_python_int_renders():
    """A numpy int64 seed wrapped in the scene's seed * 1000 + 7 (a RuntimeWarning and another
    scene than the same seed given as a Python int)."""
    seed = 2**62
    a = data_synth.render("ring", seed=seed, size=SMALL, n_robots=2, cache=False)
    b = data_synth.render("ring", seed=np.int64(seed), size=SMALL, n_robots=2, cache=False)
    assert type(b.seed) is int
    assert all(np.array_equal(x.image, y.image) for x, y in zip(a.views, b.views, strict=True))
    r, _ = data_synth.render_robot(1, "ring", seed=np.uint64(seed), size=SMALL, n_robots=2)
    assert np.array_equal(r.image, a.views[1].image)
