"""clean-db --comm-graph that leaves images in more groups than the database's verified
matches: every link between the groups is cut (not-comm-edge) and COLMAP's mapper on OUT.db
cannot put the groups in one model; it was done without a word, where run-images warns of a
comm graph in pieces. A graph that splits only what the matches already split is not warned."""

import json

import numpy as np

from pipeline import colmap
from pipeline.__main__ import main
from pipeline.types import Features, Links, View


def _db(path, rows):
    rng = np.random.default_rng(0)
    views, feats = [], []
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    for k in range(4):
        views.append(View(f"v{k}.jpg", np.zeros((240, 320, 3), np.uint8), K))
        kp = rng.uniform([0, 0], [319, 239], size=(20, 2)).astype(np.float32)
        feats.append(Features(kp, np.zeros((20, 128), np.float32), np.ones(20, np.float32),
                              "sift"))
    ci, fi, cj, fj = np.array(rows).T
    colmap.write_database(path, views, feats, Links(ci, fi, cj, fj))


def _split_warnings(err):
    return [w for w in err.splitlines() if "splits the" in w]


def test_a_comm_graph_that_splits_matched_images_is_warned(tmp_path, capsys):
    src = tmp_path / "in.db"
    _db(src, [(a, r, b, r) for a, b in ((0, 1), (1, 2), (2, 3)) for r in range(10)])
    graph = tmp_path / "g.csv"
    graph.write_text("v0.jpg,v1.jpg\nv2.jpg,v3.jpg\n")  # no edge 1-2
    report = tmp_path / "r.json"
    assert main(["clean-db", str(src), "--out", str(tmp_path / "o.db"), "--comm-graph",
                 str(graph), "--report", str(report), "--no-rerun"]) == 0
    message = ("the comm graph splits the 4 images into 2 groups that never match each other: "
               "their features cannot be associated across the groups (the database's "
               "verified matches join them in 1; add the missing edges to --comm-graph, or "
               "leave it out)")
    assert _split_warnings(capsys.readouterr().err) == [f"warning: {message}"]
    summary = json.loads(report.read_text())
    assert summary["cut"]["not-comm-edge"] == 10
    assert {"code": "logged", "message": message} in summary["warnings"]


def test_a_comm_graph_that_splits_only_unmatched_images_is_not_warned(tmp_path, capsys):
    src = tmp_path / "in.db"
    _db(src, [(a, r, b, r) for a, b in ((0, 1), (2, 3)) for r in range(10)])  # two scenes
    graph = tmp_path / "g.csv"
    graph.write_text("v0.jpg,v1.jpg\nv2.jpg,v3.jpg\n")
    assert main(["clean-db", str(src), "--out", str(tmp_path / "o.db"), "--comm-graph",
                 str(graph), "--no-rerun"]) == 0
    assert _split_warnings(capsys.readouterr().err) == []
