"""Small hloc-style files for the clean-h5 tests of this folder: ``write_h5`` writes a
features.h5 of ``names`` (``m`` random keypoints each, with descriptors if asked) and a
matches.h5 of the pairs a-b, b-c, a-c; ``run_clean_h5`` runs ``clean-h5`` on them."""

import h5py
import numpy as np

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair

PAIRS = ((0, 1), (1, 2), (0, 2))


def write_h5(d, names, m: int, matches0, descriptors: bool = False):
    """``features.h5`` and ``matches.h5`` in ``d``; ``matches0(k)`` gives the ``k``-th pair's
    (of :data:`PAIRS`) matches0 array. Returns their paths."""
    feats, matches = d / "features.h5", d / "matches.h5"
    rng = np.random.default_rng(0)
    with h5py.File(feats, "w") as fd:
        for name in names:
            g = fd.create_group(name)
            g.create_dataset("keypoints", data=rng.uniform(0, 100, (m, 2)).astype(np.float32))
            if descriptors:
                g.create_dataset("descriptors", data=rng.uniform(0, 1, (8, m)).astype(np.float32))
    with h5py.File(matches, "w") as fd:
        for k, (i, j) in enumerate(PAIRS):
            fd.create_group(names_to_pair(names[i], names[j])).create_dataset(
                "matches0", data=matches0(k))
    return feats, matches


def first_matched(m: int, k: int, dtype=np.int32):
    """A matches0 of ``m`` entries whose first ``k`` keypoints match the same in the other
    image, the others none (-1)."""
    m0 = np.full(m, -1, dtype)
    m0[:k] = np.arange(k)
    return m0


def run_clean_h5(capsys, tmp_path, feats, matches):
    """``clean-h5`` on the two files into ``tmp_path/out.h5``: (exit code, captured output,
    the output's path)."""
    out = tmp_path / "out.h5"
    code = main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--out", str(out), "--no-rerun"])
    return code, capsys.readouterr(), out
