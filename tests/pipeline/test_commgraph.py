"""pipeline.commgraph: graph kinds, the one file reader, the one checker."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from pipeline.commgraph import check_comm_edges, comm_graph, graph_edges, read_comm_graph
from pipeline.errors import InputError


def write(tmp_path, text, name):
    (tmp_path / name).write_text(text)
    return tmp_path / name


# ------------------------------------------------------------------------------------ comm graph

NAMES6 = [f"im{k}.jpg" for k in range(6)]


def test_named_graphs_hand_computed():
    assert comm_graph("ring", NAMES6[:4]).tolist() == [[0, 1], [0, 3], [1, 2], [2, 3]]
    assert comm_graph("ring2", NAMES6[:5]).tolist() == [
        [0, 1], [0, 2], [0, 3], [0, 4], [1, 2], [1, 3], [1, 4], [2, 3], [2, 4], [3, 4]]
    assert comm_graph("ring2", NAMES6).tolist() == [
        [0, 1], [0, 2], [0, 4], [0, 5], [1, 2], [1, 3], [1, 5], [2, 3], [2, 4], [3, 4], [3, 5],
        [4, 5]]
    assert comm_graph("complete", NAMES6[:3]).tolist() == [[0, 1], [0, 2], [1, 2]]
    assert comm_graph("ring", NAMES6[:2]).tolist() == [[0, 1]]
    # seq (name order), K=2: 0 picks 1,2; 1 picks 0,2; 2 picks 1,3; 3 picks 2,4; 4 picks 3,2
    assert comm_graph("seq:2", NAMES6[:5]).tolist() == [
        [0, 1], [0, 2], [1, 2], [2, 3], [2, 4], [3, 4]]
    # K=1 ties go to the lower index: 1 picks 0, 2 picks 1, ...
    assert comm_graph("seq:1", NAMES6[:4]).tolist() == [[0, 1], [1, 2], [2, 3]]
    assert comm_graph("seq:99", NAMES6[:4]).tolist() == comm_graph("complete", NAMES6[:4]).tolist()


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 40), k=st.integers(1, 8),
       kind=st.sampled_from(["ring", "ring2", "complete", "seq"]))
def test_graph_kinds_are_simple_connected_graphs(n, k, kind):
    spec = f"seq:{k}" if kind == "seq" else kind
    e = comm_graph(spec, [str(i) for i in range(n)])
    assert e.dtype == np.int64 and e.ndim == 2 and e.shape[1] == 2
    assert (e[:, 0] < e[:, 1]).all() and (e >= 0).all() and (e < n).all()
    assert len(np.unique(e, axis=0)) == len(e)
    adj = csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    assert connected_components(adj, directed=False)[0] == 1
    deg = np.bincount(e.ravel(), minlength=n)
    if kind == "ring" and n >= 3:
        assert (deg == 2).all()
    if kind == "complete":
        assert len(e) == n * (n - 1) // 2
    if kind == "seq":
        assert (deg >= min(k, n - 1)).all()
    if kind == "ring2":
        ring = {tuple(r) for r in comm_graph("ring", [str(i) for i in range(n)]).tolist()}
        assert ring <= {tuple(r) for r in e.tolist()}


def test_graph_file_with_names_indices_header_and_comments(tmp_path):
    f = tmp_path / "edges.csv"
    f.write_text("cam_i,cam_j\n# a comment\nim0.jpg, im2.jpg\n3 1\n\nim5.jpg,0\n2,im0.jpg\n")
    assert comm_graph(f, NAMES6).tolist() == [[0, 2], [0, 5], [1, 3]]


def test_graph_file_naming_unknown_image(tmp_path):
    f = tmp_path / "edges.csv"
    f.write_text("im0.jpg,im1.jpg\nim1.jpg,castle.jpg\n")
    with pytest.raises(InputError, match=r"edges\.csv, line 2: image 'castle\.jpg' is not one of the"):
        comm_graph(f, NAMES6)


@pytest.mark.parametrize("text, match", [
    ("0,9\n", "line 1: camera index 9 out of range 0..5"),
    ("0,1\n2,2\n", "line 2: self-edge"),
    ("0,1,2\n", "line 1: .* must hold two cameras"),
    ("# nothing\n", "holds no edge"),
    ("\uff10,1\n", "line 1: .* is not one of the 6 images"),  # a full-width digit
])
def test_graph_file_errors(tmp_path, text, match):
    f = tmp_path / "g.txt"
    f.write_text(text)
    with pytest.raises(InputError, match=match):
        comm_graph(f, NAMES6)


@pytest.mark.parametrize("text, match", [
    ("r0,r1,r2\n", "line 1: .* must hold two robots 'cam_i,cam_j' \\(indices or sub-folder names\\)"),
    ("r0,r1\nr1,r1\n", "line 2: self-edge .* robot 1 twice\\); a robot cannot be its own"),
    ("0,5\n", "line 1: robot index 5 out of range 0..2 \\(3 robots\\)"),
])
def test_graph_file_errors_of_a_team_name_its_robots(tmp_path, text, match):
    """run-images --sequence: the graph joins robots named by their sub-folders, not images."""
    f = tmp_path / "g.txt"
    f.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        comm_graph(f, ["r0", "r1", "r2"], what="robot")
    assert "camera" not in str(err.value) and "image" not in str(err.value)


@pytest.mark.parametrize("spec", ["star", "seq:0", "seq:x", "seq:", "knn:0", "knn:2"])
def test_unknown_graph_kind(spec):
    with pytest.raises(InputError, match="graph"):
        comm_graph(spec, NAMES6)


def test_knn_for_robots_names_the_robots_graph_and_where_knn_belongs():
    """The robots of frame sequences take a communication graph; knn:K is for photos."""
    with pytest.raises(InputError, match=r"with --sequence the graph is the robots' "
                                         r"communication graph, a kind \(line, .*seq:K\)") as e:
        comm_graph("knn:1", ["r0", "r1", "r2"], what="robot")
    assert "for unordered photos" in str(e.value) and "features" not in str(e.value)
    with pytest.raises(InputError, match="needs the images' features"):
        comm_graph("knn:1", ["a.jpg", "b.jpg", "c.jpg"])


@pytest.mark.parametrize("spec", ["", " "])
def test_an_empty_graph_is_named_empty_not_a_folder(spec, tmp_path, monkeypatch):
    """--graph '' (an unset shell variable) was refused as 'a folder': Path('') is the
    current folder."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match=rf"^graph '{spec}' is empty; give a kind \(line, ring"):
        comm_graph(spec, NAMES6)


def test_graph_needs_two_cameras():
    with pytest.raises(InputError, match="at least two cameras, got 1"):
        comm_graph("ring", ["a"])


def test_graph_of_robots_needs_two_robots_not_cameras(tmp_path):
    """The nodes of a team's graph (run-images --sequence) are robots: the message says so."""
    for graph in ("ring", write(tmp_path, "r0,r0\n", "g.csv")):
        with pytest.raises(InputError, match="^a comm graph needs at least two robots, got 1$"):
            comm_graph(graph, ["r0"], what="robot")


def test_comm_graph_csv(tmp_path):
    e = read_comm_graph(write(tmp_path, "cam_i,cam_j\n1,0\n1,2\n0,1\n", "g.csv"))
    assert e.tolist() == [[0, 1], [1, 2]]
    for text, message in [("0,0\n", "own neighbour"), ("0,1,2\n", "3 columns"),
                          ("0,a\n", "not an integer")]:
        with pytest.raises(InputError, match=message):
            read_comm_graph(write(tmp_path, text, "g.csv"))


def test_huge_ids_are_named_not_overflowing(tmp_path):
    """Regression: a 20-digit id raised OverflowError deep inside numpy (found by fuzzing)."""
    with pytest.raises(InputError, match="cam_j 99999999999999999999 is too large"):
        read_comm_graph(write(tmp_path, "0,99999999999999999999\n", "g.csv"))


# ------------------------------------------------------------------ communication graph checks


def test_check_comm_edges_sorts_and_keeps_order():
    e = check_comm_edges([[2, 0], [0, 1]], 3)
    np.testing.assert_array_equal(e, [[0, 2], [0, 1]])
    assert check_comm_edges([], 3).shape == (0, 2)


@pytest.mark.parametrize("edges,match", [
    ([[0, 5]], r"\(0, 5\) names an unknown camera; camera ids are 0..2"),
    ([[-1, 0]], "unknown camera"),
    ([[1, 1]], r"\(1, 1\) is a self-edge"),
    ([[0, 1], [1, 0]], r"\(0, 1\) is listed more than once"),
    ([[0, 1, 2]], r"shape \(E, 2\)"),
    ([[0.5, 1]], "integer camera ids"),
])
def test_bad_comm_edges_are_named(edges, match):
    with pytest.raises(InputError, match=match):
        check_comm_edges(edges, 3)


def test_kinds_of_the_small_cases():
    """One definition for every n: the rule, then self-loops dropped and each edge once."""
    assert graph_edges("ring", 1).tolist() == [] and graph_edges("line", 1).tolist() == []
    assert graph_edges("ring", 2).tolist() == [[0, 1]] == graph_edges("ring2", 2).tolist()
    assert graph_edges("ring", 3).tolist() == graph_edges("complete", 3).tolist()
    assert graph_edges("ring2", 4).tolist() == graph_edges("complete", 4).tolist()
    for n in range(2, 9):
        names = [str(k) for k in range(n)]
        for kind in ("ring", "ring2", "complete", "line", "seq:2", "ring+triangles"):
            assert comm_graph(kind, names).tolist() == graph_edges(kind, n).tolist()


def test_edge_array_duplicates_are_rejected_but_file_repeats_merged(tmp_path):
    from pipeline.commgraph import comm_edges_for
    from pipeline.types import Links

    links = Links([0], [0], [1], [0])
    with pytest.raises(InputError, match=r"\(0, 1\) is listed more than once"):
        comm_edges_for([1, 1], links, [[0, 1], [1, 0]])
    assert read_comm_graph(write(tmp_path, "0,1\n1,0\n", "g.csv")).tolist() == [[0, 1]]


def test_the_diameter_bound_of_the_time_guard():
    from pipeline.commgraph import diameter_lower_bound

    path = np.array([[i, i + 1] for i in range(50)])
    assert diameter_lower_bound(51, path) == 50
    assert diameter_lower_bound(60, path) == 50  # isolated cameras beside it
    ring = np.array([[i, (i + 1) % 8] for i in range(8)])
    assert diameter_lower_bound(8, ring) == 4
    two = np.r_[path, [[51, 52]]]  # two components: the larger diameter
    assert diameter_lower_bound(53, two) == 50
    assert diameter_lower_bound(3, np.zeros((0, 2), int)) == 0


def test_a_graph_file_of_robots_names_robots_in_its_errors(tmp_path):
    from pipeline.commgraph import comm_graph

    f = tmp_path / "g.csv"
    f.write_text("r0,r5\n")
    with pytest.raises(InputError, match=r"robot 'r5' is not one of the 3 robots \(r0, r1, r2\)"):
        comm_graph(f, ["r0", "r1", "r2"], what="robot")
    with pytest.raises(InputError, match="image 'r5' is not one of the 3 images"):
        comm_graph(f, ["r0", "r1", "r2"])


def test_names_of_digits_mixed_with_indices_are_refused_as_ambiguous(tmp_path):
    names = ["10", "2", "9"]  # sub-folders of robots in name order
    g = tmp_path / "g.txt"
    g.write_text("0,2\n")  # '0' an index; '2' the name of robot 1 and the index of robot 2
    with pytest.raises(InputError, match=r"robot '2' is ambiguous: it is the name of robot 1 "
                                         r"and the index of robot 2 \('9'\)"):
        read_comm_graph(g, names, what="robot")
    g.write_text("10,2\n2,9\n")  # names only
    assert read_comm_graph(g, names, what="robot").tolist() == [[0, 1], [1, 2]]
    g.write_text("0,1\n")  # indices only, none of them a name
    assert read_comm_graph(g, names, what="robot").tolist() == [[0, 1]]
    # names equal to their own index are no ambiguity
    assert read_comm_graph(g, ["0", "1", "x"], what="robot").tolist() == [[0, 1]]


@pytest.mark.parametrize("edges,kind", [({(0, 1)}, "set"), (((0, 1) for _ in "x"), "generator"),
                                        ({0: 1}, "dict")])
def test_edges_of_a_python_set_or_generator_are_named_by_type(edges, kind):
    # numpy wrapped them whole: 'must have shape (E, 2), got ()'
    from pipeline.consistency.engines.driver import resolve_conflicts
    from pipeline.types import Links

    with pytest.raises(InputError, match=rf"communication edges given as a {kind}: give a list "
                                         r"of \(camera i, camera j\) pairs or an \(E, 2\)"):
        resolve_conflicts([1, 1], edges, Links([0], [0], [1], [0]))


@pytest.mark.parametrize("n", [3.5, -3, "4", True])
def test_graph_edges_refuses_a_number_of_robots_that_is_not_one(n):
    """int(3.5) made a ring of 3 robots, a negative n a graph of none, silently."""
    with pytest.raises(InputError, match=rf"graph 'ring': n = {n!r} robots; give a whole number"):
        graph_edges("ring", n)


def test_graph_edges_takes_numpy_integers():
    assert graph_edges("ring", np.int32(3)).tolist() == [[0, 1], [0, 2], [1, 2]]
    assert graph_edges("line", 0).tolist() == []
