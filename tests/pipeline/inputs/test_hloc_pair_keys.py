"""pipeline.inputs.hloc with --pairs: two pairs that hloc stores under one group (a '/' inside
an image name is written '-') are refused, not read as one pair with the other left empty;
a pair without a group names the groups looked for and what to do."""

import h5py
import numpy as np

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair

M = 16


def _write(d, names, stored):
    feats, matches = d / "features.h5", d / "matches.h5"
    rng = np.random.default_rng(0)
    with h5py.File(feats, "w") as fd:
        for name in names:
            fd.create_group(name).create_dataset(
                "keypoints", data=rng.uniform(0, 100, (M, 2)).astype(np.float32))
    with h5py.File(matches, "w") as fd:
        for a, b in stored:
            m0 = np.full(M, -1, np.int32)
            m0[:6] = np.arange(6)
            fd.create_group(names_to_pair(a, b)).create_dataset("matches0", data=m0)
    return feats, matches


def _run(capsys, d, feats, matches, pairs_text):
    pairs = d / "pairs.txt"
    pairs.write_text(pairs_text)
    out = d / "out.h5"
    code = main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--pairs", str(pairs), "--out", str(out), "--no-rerun"])
    captured = capsys.readouterr()
    return code, captured, out, pairs


def test_two_pairs_of_one_group_are_refused(tmp_path, capsys):
    # 'a/b.jpg' and 'a-b.jpg' both flatten to 'a-b.jpg': the pairs with c.jpg share one group
    names = ["a/b.jpg", "a-b.jpg", "c.jpg"]
    feats, matches = _write(tmp_path, names, [("a/b.jpg", "c.jpg")])
    code, captured, out, pairs = _run(capsys, tmp_path, feats, matches,
                                      "a/b.jpg c.jpg\na-b.jpg c.jpg\n")
    assert code == 2 and not out.exists() and "Traceback" not in captured.err
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {matches}: pairs a/b.jpg c.jpg and a-b.jpg c.jpg of {pairs} are both stored "
        "as group 'a-b.jpg/c.jpg' (hloc writes a '/' inside an image name as '-'), so one group "
        "holds the matches of one of them only; rename one of the images (and match again), or "
        "remove one of the lines")


def test_one_of_the_two_pairs_alone_is_read(tmp_path, capsys):
    names = ["a/b.jpg", "a-b.jpg", "c.jpg"]
    feats, matches = _write(tmp_path, names, [("a/b.jpg", "c.jpg")])
    code, captured, out, _ = _run(capsys, tmp_path, feats, matches, "a-b.jpg c.jpg\n")
    assert code == 0 and out.exists()
    assert captured.out.startswith("3 images, 1 image pairs, 6 matches")


def test_a_pair_without_a_group_names_the_groups_and_what_to_do(tmp_path, capsys):
    names = ["a.jpg", "b.jpg", "c.jpg"]
    feats, matches = _write(tmp_path, names, [("a.jpg", "b.jpg"), ("b.jpg", "c.jpg")])
    code, captured, out, pairs = _run(capsys, tmp_path, feats, matches,
                                      "a.jpg b.jpg\na.jpg c.jpg\n")
    assert code == 2 and not out.exists()
    assert captured.err.strip().splitlines()[-1] == (
        f"error: {matches}: no matches stored for pair a.jpg c.jpg of {pairs} (no group "
        "'a.jpg/c.jpg' nor 'c.jpg/a.jpg'); match that pair, or remove its line")
