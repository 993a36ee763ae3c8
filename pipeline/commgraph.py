"""The communication graph ``G_com``: its kinds, its file format and its one checker.

Robot ``i`` may talk to robot ``j`` only along an edge of ``G_com`` (Aragüés et al., Sec. II:
local association is computed only between neighbours; Montijano et al., Sec. II: the
consensus exchanges values between neighbours). Every stage that takes a communication graph
gets it from here:

* :func:`graph_edges` — the named kinds ``line``, ``ring``, ``ring2``, ``complete``,
  ``ring+triangles`` (formation (b) of :mod:`data_synth.formations`, which defines the four
  graphs of the paper's Fig. 4: the figure is not in its text), ``geometric`` (needs positions) and
  ``seq:K``;
* :func:`comm_graph` — a kind or a file, for a set of named images (``run-images``), plus
  ``knn:K`` (neighbours by image similarity, :mod:`pipeline.matching.retrieval`);
* :func:`read_comm_graph` — the one file reader (indices, or image names when given);
* :func:`check_comm_edges` — the one checker of an edge array;
* :func:`neighbour_table` — every robot's neighbours (the simulated network, ``TEAM.json``);
* :func:`comm_edges_for` — the checked graph of the consistency stage, with every link on an
  edge.

Definitions (stated)
--------------------
A graph on ``n`` robots is a set of undirected edges ``(i, j)``, ``0 <= i < j < n``. The
kinds are built from their rule and then reduced to that form (self-loops dropped, each edge
once), which fixes the small cases: ``ring`` is ``(i, i + 1 mod n)`` — no edge for
``n = 1``, the single edge for ``n = 2``, the triangle for ``n = 3``; ``ring2`` adds
``(i, i + 2 mod n)`` and is the complete graph for ``n <= 4``; ``ring+triangles`` adds
``(k, k + 2)`` for ``k ≡ 0 mod 3``, ``k + 2 < n``; ``seq:K`` links each camera to the ``K``
cameras nearest in index (capture) order, ties to the lower index, not wrapped (for ordered
sequences); ``knn:K`` links each image to its ``K`` most similar images by a global descriptor
of its features (for unordered photos, whose names say nothing); ``geometric``
links robots closer than a radius drawn from the seed between 1.0 and 2.5 times the smallest
radius that keeps the graph connected.

Self-loops and duplicated edges (one policy)
--------------------------------------------
* A self-loop ``(i, i)`` is an error everywhere (a camera is not its own neighbour).
* An edge *array* handed to a stage is a set: an edge listed twice (``(i, j)`` and ``(j, i)``
  are the same edge) is an :class:`~pipeline.errors.InputError` naming it, never dropped
  silently.
* A graph *file* is a list of lines, where writing a symmetric adjacency list is natural:
  :func:`read_comm_graph` merges a line that repeats an edge (in either orientation) and
  returns the set, sorted.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial.distance import pdist, squareform

from pipeline.errors import InputError
from pipeline.inputs.linkscsv import MAX_ID

__all__ = ["GRAPH_KINDS", "graph_edges", "comm_graph", "names_graph_file", "read_comm_graph",
           "check_comm_edges", "comm_edges_for", "diameter_lower_bound", "links_off_graph",
           "edge_set", "positive_k", "graph_parts"]

#: Kinds built by :func:`graph_edges` (plus ``ring+triangles`` and ``seq:K``).
GRAPH_KINDS = ("line", "ring", "ring2", "complete", "geometric")
_ALL_KINDS = GRAPH_KINDS + ("ring+triangles", "seq:K")


# ---------------------------------------------------------------------------------- kinds

def edge_set(pairs) -> np.ndarray:
    """``(E, 2)`` int64 pairs reduced to the set form: ``i < j``, no self-loop, sorted, unique."""
    e = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    e = np.sort(e[e[:, 0] != e[:, 1]], axis=1)
    return np.unique(e, axis=0).reshape(-1, 2)


def _seq_edges(n: int, k: int) -> np.ndarray:
    """Each camera linked to its ``k`` nearest cameras in index order (union of choices)."""
    idx = np.arange(n)
    dist = np.abs(idx[:, None] - idx[None, :]).astype(np.float64)
    # ties broken towards the lower index: key = distance, then index / n
    key = dist + idx[None, :] / (2.0 * n)
    np.fill_diagonal(key, np.inf)
    nearest = np.argsort(key, axis=1, kind="stable")[:, :k]
    return edge_set(np.stack([np.repeat(idx, k), nearest.reshape(-1)], axis=1))


def graph_edges(kind: str, n: int, centres: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
    """Edges of a communication graph of a named kind on ``n`` robots (module docstring).

    Parameters
    ----------
    kind : str
        ``line``, ``ring``, ``ring2``, ``complete``, ``ring+triangles``, ``geometric`` or
        ``seq:K`` (``K`` a positive integer).
    n : int
    centres : ndarray, (n, >= 2), optional — robot positions, needed by ``geometric``
    seed : int — draws the radius of ``geometric``

    Returns
    -------
    edges : ndarray, (E, 2) int64, ``i < j``, sorted, unique

    Raises
    ------
    InputError
        Unknown kind, a bad ``K``, ``geometric`` without positions, ``n`` not a whole number
        ``>= 0``.

    Examples
    --------
    >>> graph_edges("ring", 4).tolist()
    [[0, 1], [0, 3], [1, 2], [2, 3]]
    >>> graph_edges("seq:2", 4).tolist()
    [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]
    >>> graph_edges("ring", 2).tolist(), graph_edges("ring", 1).tolist()
    ([[0, 1]], [])
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        # int(3.5) made a graph of 3 robots, a negative n one of none
        raise InputError(f"graph {kind!r}: n = {n!r} robots; give a whole number >= 0")
    n = int(n)
    idx = np.arange(n)
    ring = np.stack([idx, (idx + 1) % n], axis=1)
    if kind == "line":
        e = ring[:-1]
    elif kind == "ring":
        e = ring
    elif kind == "ring+triangles":
        k = np.arange(0, n - 2, 3)
        e = np.concatenate([ring, np.stack([k, k + 2], axis=1)])
    elif kind == "ring2":
        e = np.concatenate([ring, np.stack([idx, (idx + 2) % n], axis=1)])
    elif kind == "complete":
        e = np.stack(np.triu_indices(n, k=1), axis=1)
    elif kind == "geometric":
        if centres is None:
            raise InputError("graph 'geometric' needs the robot positions")
        D = squareform(pdist(np.asarray(centres)[:, :2]))
        r_conn = float(minimum_spanning_tree(D).toarray().max())
        r = r_conn * np.random.default_rng([seed, 4]).uniform(1.0, 2.5)
        e = np.stack(np.nonzero(np.triu(D <= r + 1e-9, k=1)), axis=1)
    elif kind.startswith("seq:"):
        return _seq_edges(n, min(positive_k(kind), max(n - 1, 0)))
    else:
        raise InputError(f"unknown graph kind {kind!r}; choose one of {', '.join(_ALL_KINDS)}")
    return edge_set(e)


def positive_k(spec: str) -> int:
    """The ``K`` of a ``seq:K`` or ``knn:K`` graph kind; InputError unless a positive integer.

    >>> positive_k("knn:4")
    4
    """
    k_text = spec.split(":", 1)[1]
    if not k_text.isdigit() or int(k_text) < 1:
        raise InputError(f"graph {spec!r}: K must be a positive integer, e.g. "
                         f"{spec.split(':', 1)[0]}:4")
    return int(k_text)


def _built_kind(spec: str) -> bool:
    """``spec`` is a kind :func:`comm_graph` builds from the image count alone."""
    return spec in _ALL_KINDS and spec not in ("geometric", "seq:K") or spec.startswith("seq:")


def names_graph_file(kind_or_file: str | Path) -> bool:
    """True when :func:`comm_graph` reads ``kind_or_file`` as a graph file: an existing file
    whose name is no kind (a kind wins over a file of its name)."""
    spec = str(kind_or_file)
    return not (_built_kind(spec) or spec.startswith("knn:")) and bool(spec.strip()) \
        and Path(spec).is_file()


def comm_graph(kind_or_file: str | Path, names: list[str], knn=None,
               what: str = "image", *, offers_knn: bool = True) -> np.ndarray:
    """The communication graph the user chose for a set of images, as undirected edges.

    Parameters
    ----------
    kind_or_file : str or Path
        A kind of :func:`graph_edges` other than ``geometric`` (images have no positions);
        ``knn:K``: each image picks the ``K`` most similar images by a global descriptor of
        its features (:func:`pipeline.matching.retrieval.knn_edges`), for unordered photos; or a file
        of :func:`read_comm_graph` (indices in name order or image names).
    names : list[str], (n,) — image names in camera order
    knn : callable ``K -> (E, 2) edges``, optional — needed by ``knn:K`` only: the ``K``
        most similar images of each (e.g. ``knn_edges`` of the images' features)
    what : str — what the named nodes are, in the messages of a bad file (``robot`` for the
        robots of a team's frame sequences)
    offers_knn : bool — the command takes ``knn:K`` (``run-images``; not ``run-landmarks``,
        nor a team's robots), so that a message listing the kinds names it

    Returns
    -------
    edges : ndarray, (E, 2) int64, ``i < j``, sorted, no duplicates

    Raises
    ------
    InputError
        Fewer than two cameras (robots), an unknown kind that is no file either, a bad ``K``, or any
        error of :func:`read_comm_graph`.

    Examples
    --------
    >>> comm_graph("ring", ["a", "b", "c", "d"]).tolist()
    [[0, 1], [0, 3], [1, 2], [2, 3]]
    """
    n = len(names)
    if n < 2:
        raise InputError(f"a comm graph needs at least two {_node(what)[0]}s, got {n}")
    spec = str(kind_or_file)
    if _built_kind(spec):
        return graph_edges(spec, n)
    if spec.startswith("knn:"):
        k = positive_k(spec)
        if knn is None and what == "robot":
            kinds = ", ".join(k for k in _ALL_KINDS if k != "geometric")
            raise InputError(f"graph {spec!r}: with --sequence the graph is the robots' "
                             f"communication graph, a kind ({kinds}) or a file of "
                             "'robot_i,robot_j' lines (sub-folder names or indices); knn:K "
                             "picks neighbours by image similarity, for unordered photos "
                             "(run-images without --sequence)")
        if knn is None:
            raise InputError(f"graph {spec!r} picks neighbours by image similarity and needs "
                             f"the images' features; use seq:K for neighbours in name order")
        return knn(k)
    kinds = ", ".join([k for k in _ALL_KINDS if k != "geometric"]
                      + (["knn:K"] if offers_knn and what != "robot" else []))
    if not spec.strip() and not Path(spec).is_file():  # Path('') is the current folder
        raise InputError(f"graph {spec!r} is empty; give a kind ({kinds}) or a file of "
                         "'cam_i,cam_j' lines")
    path = Path(kind_or_file)
    if path.is_dir():
        raise InputError(f"graph {spec!r} is a folder, not a file; give a kind or a file of "
                         "'cam_i,cam_j' lines")
    if not path.is_file():
        raise InputError(
            f"graph {spec!r}: not one of {kinds} and no such file; give a kind "
            f"or a file of 'cam_i,cam_j' lines (indices or {_node(what)[1]})")
    return read_comm_graph(path, names, what)


# ----------------------------------------------------------------------------------- file

def _node(what: str) -> tuple[str, str]:
    """What an edge joins and what names it, in messages: an image is a camera, named by its
    file; a team's robot is named by its sub-folder."""
    return {"image": ("camera", "image names"),
            "robot": ("robot", "sub-folder names")}.get(what, (what, f"{what} names"))


def _names_by_form(names: list[str]) -> dict[str, int]:
    """``{name: index}`` of ``names``, and of the NFC form of each name whose form no other
    name shares: a name typed in a graph file and the file name it means may encode an
    accent two ways (macOS writes file names decomposed, NFD; an editor types them composed,
    NFC), the same text printed alike in every message that said it was not one of them."""
    import unicodedata

    by_name = {name: k for k, name in enumerate(names)}
    forms: dict[str, list[int]] = {}
    for k, name in enumerate(names):
        forms.setdefault(unicodedata.normalize("NFC", name), []).append(k)
    for form, ks in forms.items():
        if len(ks) == 1:
            by_name.setdefault(form, ks[0])
    return by_name


def _camera(path, line_no, column, tok, names, by_name, what: str = "image") -> int:
    """One end of an edge line: an image name (when names are known, in either Unicode form:
    :func:`_names_by_form`) or a 0-based index."""
    import unicodedata

    if by_name is not None:
        for form in (tok, unicodedata.normalize("NFC", tok)):
            if form in by_name:
                return by_name[form]
    if not re.fullmatch(r"-?[0-9]+", tok):  # ASCII digits (\d takes other scripts too)
        if by_name is not None:
            n = len(names)
            shown = ", ".join(names[:5]) + (", ..." if n > 5 else "")
            raise InputError(f"{path}, line {line_no}: {what} {tok!r} is not one of the {n} "
                             f"{what}s ({shown})")
        raise InputError(f"{path}, line {line_no}: {column} {tok!r} is not an integer "
                         f"{_node(what)[0]} id; ids are 0-based integers")
    k = int(tok)
    if k < 0:
        raise InputError(f"{path}, line {line_no}: {column} {k} is negative; ids are 0-based")
    if k > MAX_ID:
        raise InputError(f"{path}, line {line_no}: {column} {k} is too large; ids must be at "
                         f"most {MAX_ID}")
    if names is not None and k >= len(names):
        n = len(names)
        raise InputError(f"{path}, line {line_no}: {_node(what)[0]} index {k} out of range "
                         f"0..{n - 1} ({n} {what}s)")
    return k


def _refuse_ambiguous(path, rows, names, by_name, what: str) -> None:
    """A file that gives some camera by its index (a token no name equals) must not hold a token
    that is both a name and the index of another camera: names of digits (sub-folders ``10``,
    ``2``, ``9``) would make ``0,2`` mean robot ``10`` and robot ``2`` (index 1), not indices
    0 and 2. A file of names only, or of indices only, is read as before."""
    tokens = [(line_no, tok) for line_no, _, toks in rows for tok in toks]
    by_index = [(line_no, tok) for line_no, tok in tokens
                if tok not in by_name and re.fullmatch(r"[0-9]+", tok)]
    if not by_index:
        return
    for line_no, tok in tokens:
        if tok in by_name and re.fullmatch(r"[0-9]+", tok) and int(tok) < len(names) \
                and int(tok) != by_name[tok]:
            raise InputError(
                f"{path}, line {line_no}: {what} {tok!r} is ambiguous: it is the name of {what} "
                f"{by_name[tok]} and the index of {what} {int(tok)} ({names[int(tok)]!r}), and the "
                f"file gives {what}s by index too (line {by_index[0][0]}: {by_index[0][1]!r}); "
                f"write every {what} by its name, or every one by its index")


def read_comm_graph(path: str | os.PathLike, names: list[str] | None = None,
                    what: str = "image") -> np.ndarray:
    """Read a communication-graph file: one edge ``cam_i,cam_j`` per line.

    Format: two cameras per line separated by a comma, tab or spaces (CSV double quotes for
    names holding spaces, commas or ``#``, see :mod:`pipeline.inputs.csvfields`); each a 0-based index,
    or, when ``names`` is given, an image name (a token equal to an image name is that image,
    otherwise it must be an index; a file that gives some image by index may not hold a token
    that is also the name of another image: names of digits make it ambiguous). ``#`` starts a comment; blank lines and a first line
    ``cam_i,cam_j`` are skipped. A line repeating an edge (either orientation) is merged.

    Parameters
    ----------
    path : path of a UTF-8 text file
    names : list[str] or None — image names in camera order (also bounds the indices)
    what : str — what a node is in messages (``image``; ``robot`` for a team's sequences)

    Returns
    -------
    edges : ndarray, (E, 2) int64, ``i < j``, sorted, unique, ``E >= 1``

    Raises
    ------
    InputError
        Missing or non-text file, a line without exactly two cameras, a blank name (empty or
        only spaces, ``" ",b.jpg``, ``a.jpg,,b.jpg``), an unknown image name, a
        non-integer, negative, too large or out-of-range index, a self-edge, or no edge at all
        — naming the file and line.
    """
    from pipeline.inputs.csvfields import line_fields, text_lines
    from pipeline.outputs import require_input_file

    path = Path(path)
    require_input_file(path, "comm graph file")
    by_name = None if names is None else _names_by_form(names)
    rows = []
    header_allowed = True
    for line_no, raw in text_lines(path, "graph file"):
        tokens = line_fields(raw, f"{path}, line {line_no}", keep_blank=True)
        if not tokens:
            continue
        while len(tokens) > 2 and not tokens[-1]:
            tokens.pop()  # a trailing comma (a spreadsheet's empty column) holds no name
        if "" in tokens[:2]:
            col = ("cam_i", "cam_j")[tokens.index("")]
            raise InputError(f"{path}, line {line_no}: {raw.strip()!r}: {col} is a blank "
                             f"{what} name; write the {what}'s name or its index there, or "
                             "delete the line")
        if header_allowed and [t.lower() for t in tokens] == ["cam_i", "cam_j"]:
            header_allowed = False
            continue
        header_allowed = False
        if len(tokens) != 2:
            node, named = _node(what)
            raise InputError(f"{path}, line {line_no}: {raw.strip()!r} has {len(tokens)} columns; "
                             f"it must hold two {node}s 'cam_i,cam_j' (indices or {named})")
        rows.append((line_no, raw, tokens))
    if by_name is not None:
        _refuse_ambiguous(path, rows, names, by_name, what)
    edges = []
    for line_no, raw, tokens in rows:
        i, j = (_camera(path, line_no, col, tok, names, by_name, what)
                for col, tok in zip(("cam_i", "cam_j"), tokens, strict=True))
        if i == j:
            node = _node(what)[0]
            raise InputError(f"{path}, line {line_no}: self-edge {raw.strip()!r} ({path}:{line_no}: "
                             f"{node} {i} twice); a {node} cannot be its own neighbour, an edge "
                             f"joins two different {node}s")
        edges.append((i, j))
    if not edges:
        raise InputError(f"graph file {str(path)!r} holds no edge; list one 'cam_i,cam_j' "
                         "per line")
    return edge_set(edges)


# -------------------------------------------------------------------------------- checker

def check_comm_edges(comm_edges, n_cameras: int, *, what: str = "communication edge",
                     noun: str = "camera") -> np.ndarray:
    """The one checker of an edge array: ``(E, 2)`` int64, each row ``i < j``, input order.

    Parameters
    ----------
    comm_edges : array-like, (E, 2) int
        Undirected edges ``(i, j)``, each listed once in either orientation.
    n_cameras : int — ids must be ``0..n_cameras - 1``
    what, noun : str — how the error names an edge and its ends (``edge``/``node`` for the
        flat node graphs of the fusion consensus)

    Returns
    -------
    edges : ndarray, (E, 2) int64, each row sorted, in input order

    Raises
    ------
    InputError
        Wrong shape, non-integer ids, an id outside ``0..n_cameras-1``, a self-edge, or an
        edge listed twice (``(i, j)`` and ``(j, i)`` are the same edge), naming the edge.
    """
    try:
        raw = np.asarray(comm_edges)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what}s are not an (E, 2) array of {noun} ids: {exc}") from None
    if raw.ndim == 0 and raw.dtype == object:  # a set, a generator, a dict: numpy wraps it whole
        raise InputError(f"{what}s given as a {type(comm_edges).__name__}: give a list of "
                         f"({noun} i, {noun} j) pairs or an (E, 2) integer array, e.g. "
                         "[(0, 1), (1, 2)]")
    if raw.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if raw.ndim != 2 or raw.shape[1] != 2:
        raise InputError(f"{what}s must have shape (E, 2), got {raw.shape}")
    if not np.issubdtype(raw.dtype, np.integer):
        if not np.issubdtype(raw.dtype, np.floating) or not np.all(np.isfinite(raw)) \
                or not np.all(raw == np.round(raw)):
            raise InputError(f"{what}s must be integer {noun} ids, got dtype {raw.dtype}")
    edges = raw.astype(np.int64)
    n = int(n_cameras)
    bad = np.flatnonzero(((edges < 0) | (edges >= n)).any(axis=1))
    if bad.size:
        a, b = edges[bad[0]].tolist()
        raise InputError(f"{what} ({a}, {b}) names an unknown {noun}; {noun} ids are 0..{n - 1}: "
                         f"list edges between {noun}s 0..{n - 1}")
    bad = np.flatnonzero(edges[:, 0] == edges[:, 1])
    if bad.size:
        a, b = edges[bad[0]].tolist()
        raise InputError(f"{what} ({a}, {b}) is a self-edge (self-loop); a {noun} is not its own "
                         "neighbour, drop it")
    edges = np.sort(edges, axis=1)
    key = edges[:, 0] * n + edges[:, 1]
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    if (counts > 1).any():
        a, b = edges[first[np.flatnonzero(counts > 1)[0]]].tolist()
        raise InputError(f"{what} ({a}, {b}) is listed more than once; list each undirected "
                         "edge once")
    return edges


def graph_parts(n: int, edges: np.ndarray) -> int:
    """Connected components of the graph on ``n`` nodes (an isolated node is one).

    >>> graph_parts(4, np.array([[0, 1], [2, 3]]))
    2
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return int(connected_components(adj, directed=False)[0])


def split_warning(n: int, edges: np.ndarray, items: str = "images",
                  lost: str = "their features cannot be associated across the groups",
                  advice: str = "choose a denser --graph", parts: int | None = None) -> str | None:
    """The warning of a comm graph on ``n`` ``items`` that splits them into groups that never
    match each other (:func:`graph_parts`, or ``parts`` when the caller counted them), or None
    when it is connected.

    >>> split_warning(4, np.array([[0, 1], [2, 3]]))
    'the comm graph splits the 4 images into 2 groups that never match each other: their features cannot be associated across the groups (choose a denser --graph)'
    >>> split_warning(2, np.array([[0, 1]])) is None
    True
    """
    parts = graph_parts(n, edges) if parts is None else parts
    if parts <= 1:
        return None
    return (f"the comm graph splits the {n} {items} into {parts} groups that never match each "
            f"other: {lost} ({advice})")


def diameter_lower_bound(n: int, edges: np.ndarray) -> int:
    """The largest hop distance found by two breadth-first sweeps in every connected
    component of the graph on ``n`` nodes: a lower bound of the largest component's
    diameter, exact on paths and trees (the second sweep starts at a farthest node of the
    first). Linear in the nodes and edges."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if n <= 1 or not len(e):
        return 0
    graph = sp.csr_matrix((np.ones(2 * len(e), dtype=bool),
                           (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n))
    _, label = connected_components(graph, directed=False)

    def depths(sources: np.ndarray) -> np.ndarray:
        # one BFS from a virtual node n joined to one source per component
        a = np.r_[np.repeat(np.arange(n), np.diff(graph.indptr)), np.full(len(sources), n)]
        b = np.r_[graph.indices, sources]
        g = sp.csr_matrix((np.ones(len(a), dtype=bool), (a, b)), shape=(n + 1, n + 1))
        order, pred = breadth_first_order(g, n, directed=True, return_predecessors=True)
        depth = np.zeros(n + 1, dtype=np.int64)
        for u in order[1:].tolist():
            depth[u] = depth[pred[u]] + 1
        return depth[:n] - 1

    first = np.unique(label, return_index=True)[1]
    d1 = depths(first)
    far = np.lexsort((-d1, label))  # per component, a farthest node first
    starts = far[np.r_[True, label[far][1:] != label[far][:-1]]]
    return int(depths(starts).max(initial=0))


def links_off_graph(links, edges: np.ndarray, n: int) -> np.ndarray:
    """``(L,)`` bool: the links joining two cameras that are not neighbours in ``edges``."""
    if not len(links):
        return np.zeros(0, dtype=bool)
    e = np.sort(np.asarray(edges, dtype=np.int64).reshape(-1, 2), axis=1)
    return ~np.isin(links.cam_i * n + links.cam_j, e[:, 0] * n + e[:, 1])


def comm_edges_for(features_per_camera, links, comm_edges=None) -> np.ndarray:
    """The checked graph of the consistency stage: ``(E, 2)`` int64, ``i < j``, sorted.

    Parameters
    ----------
    features_per_camera : (n,) int
    links : pipeline.types.Links
    comm_edges : array_like (E, 2) or None
        ``None``: cameras sharing a link are neighbours.

    Raises
    ------
    InputError
        Any error of :func:`check_comm_edges`, or a link joining two cameras that are not
        neighbours (matching only happens on communication edges).
    """
    n = len(np.asarray(features_per_camera))
    if comm_edges is None:
        e = np.stack([links.cam_i, links.cam_j], axis=1) if len(links) else np.zeros((0, 2), np.int64)
        return np.unique(e, axis=0).astype(np.int64).reshape(-1, 2)
    e = np.unique(check_comm_edges(comm_edges, n), axis=0).reshape(-1, 2)
    bad = np.flatnonzero(links_off_graph(links, e, n))
    if bad.size:
        k = bad[0]
        raise InputError(
            f"link {k} ({links.cam_i[k]},{links.feat_i[k]})-({links.cam_j[k]},{links.feat_j[k]}) "
            f"joins cameras {links.cam_i[k]} and {links.cam_j[k]}, which are not neighbours in "
            "the communication graph; add the edge or drop the link")
    return e


def neighbour_table(edges, n: int) -> list[frozenset]:
    """Every robot's comm-graph neighbours: ``(n,)`` frozensets of robot ids, from the
    undirected ``edges`` (a self-loop, which a checked graph never holds, is no neighbour).

    >>> [sorted(k) for k in neighbour_table([[0, 1], [2, 1]], 3)]
    [[1], [0, 2], [1]]
    """
    table: list[set] = [set() for _ in range(int(n))]
    for a, b in np.asarray(edges, dtype=np.int64).reshape(-1, 2).tolist():
        if a != b:
            table[a].add(b)
            table[b].add(a)
    return [frozenset(k) for k in table]
