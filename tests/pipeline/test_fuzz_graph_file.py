"""Fuzzed ``--graph FILE`` of run-images and run-landmarks (image names or indices in name
order, one edge a line): a damaged copy of a valid file gives valid edges or an InputError
naming the file."""

import sys
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pipeline.commgraph import comm_graph, read_comm_graph

sys.path.insert(0, str(Path(__file__).parent))
from mutants import FUZZ, bytes_mutant, read_or_refuse, text_mutant  # noqa: E402

NAMES = ["a.jpg", "b.jpg", "c d.jpg", "e,f.jpg"]
VALID = ["a.jpg b.jpg\nb.jpg \"c d.jpg\"  # a comment\n\"c d.jpg\", \"e,f.jpg\"\n",
         "0 1\n1 2\n2 3\n3 0\n", "0,1\n# ring\n1,2\n"]


@FUZZ
@given(st.one_of(st.sampled_from(VALID).flatmap(text_mutant).map(
    lambda s: s.encode("utf-8", "surrogatepass")), bytes_mutant(VALID[0].encode())))
def test_a_damaged_graph_file_gives_edges_or_an_error_naming_it(content):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "graph.txt"
        path.write_bytes(content)
        e = read_or_refuse(lambda: comm_graph(str(path), NAMES), str(path))
        if e is not None:
            assert e.ndim == 2 and e.shape[1] == 2 and len(e) >= 1
            assert (e[:, 0] < e[:, 1]).all() and e.min() >= 0 and e.max() < len(NAMES)
            assert len(np.unique(e, axis=0)) == len(e)


EDGES = ["0,1\n1,2\n# a comment\n2,0\n", "cam_i,cam_j\n0 1\n3 2\n"]


@FUZZ
@given(st.one_of(st.sampled_from(EDGES).flatmap(text_mutant).map(
    lambda s: s.encode("utf-8", "surrogatepass")), bytes_mutant(EDGES[0].encode())))
def test_a_damaged_edges_file_of_camera_ids_gives_edges_or_an_error_naming_it(content):
    # resolve --comm-graph, clean-db --comm-graph: camera ids, no names
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "edges.csv"
        path.write_bytes(content)
        e = read_or_refuse(lambda: read_comm_graph(path), str(path))
        if e is not None:
            e = np.asarray(e)
            assert e.ndim == 2 and e.shape[1] == 2 and (e >= 0).all()
            assert (e[:, 0] != e[:, 1]).all()
