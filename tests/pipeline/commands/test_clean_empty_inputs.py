"""clean-h5 and clean-db on an input of no match: not an error, as resolve on an empty links
file is not; the command warns, writes the copy unchanged and an empty links.csv, exits 0.
clean-h5 stopped with 'no matches to clean' and clean-db with 'N two-view geometries, all
without inliers' (exit 2)."""
import sqlite3
import sys
from pathlib import Path

import h5py
import numpy as np

from pipeline import colmap
from pipeline.__main__ import main
from pipeline.types import Links

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1]))
from test_clean_h5 import _write  # noqa: E402
from test_colmap import _views_and_features  # noqa: E402

_HEADER = "cam_i,feat_i,cam_j,feat_j,status,reason,round,truth"
_WARNING = "warning: the input holds no link between two images: there is nothing to associate"


def test_clean_h5_of_no_match_writes_the_copy_and_warns(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    with h5py.File(matches, "a") as fd:
        fd.visititems(lambda name, obj: obj.__setitem__(Ellipsis, -1)
                      if name.endswith("/matches0") else None)
    out = tmp_path / "out.h5"
    argv = ["clean-h5", "--features", str(feats), "--matches", str(matches), "--out", str(out),
            "--no-rerun"]
    assert main(argv) == 0
    assert _WARNING in capsys.readouterr().err
    assert (tmp_path / "out.links.csv").read_text().splitlines() == [_HEADER]
    with h5py.File(matches, "r") as a, h5py.File(out, "r") as b:
        keys = []
        a.visit(lambda name: keys.append(name) if isinstance(a[name], h5py.Dataset) else None)
        assert keys and all(np.array_equal(a[k][()], b[k][()]) for k in keys)


def test_clean_db_of_no_inlier_writes_the_copy_and_warns(tmp_path, capsys):
    views, feats = _views_and_features(n=3)
    db = colmap.write_database(tmp_path / "failed.db", views, feats,
                               Links([0, 0], [1, 2], [1, 2], [2, 3]), keep=[False, False])
    out = tmp_path / "out.db"
    assert main(["clean-db", str(db), "--out", str(out), "--no-rerun"]) == 0
    assert _WARNING in capsys.readouterr().err
    assert (tmp_path / "out.links.csv").read_text().splitlines() == [_HEADER]
    query = "SELECT pair_id, rows, config FROM two_view_geometries ORDER BY pair_id"
    with sqlite3.connect(db) as a, sqlite3.connect(out) as b:
        assert a.execute(query).fetchall() == b.execute(query).fetchall() != []
