"""clean-h5: hloc's files in, the same format out, with the conflicts cut (files built here in
hloc's layout: features.h5 groups per image name with 'keypoints'; matches.h5 groups
names_to_pair(name0, name1) with 'matches0' (int16, -1 = none) and 'matching_scores0')."""

import hashlib
import json

import h5py
import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair, read_h5
from pipeline.inputs.linkscsv import read_run_links_csv

NAMES = ["a.jpg", "sub/b.jpg", "c.jpg"]  # a name with '/' is a nested group, as in hloc
M = 20


def _write(tmp_path, pairs_swapped=False, old_keys=False):
    feats, matches = tmp_path / "features.h5", tmp_path / "matches.h5"
    rng = np.random.default_rng(0)
    with h5py.File(feats, "w") as fd:
        for name in NAMES:
            g = fd.create_group(name)
            g.create_dataset("keypoints", data=rng.uniform(0, 300, (M, 2)).astype(np.float32))
            g.create_dataset("descriptors", data=rng.random((128, M)).astype(np.float16))
    # clean tracks: feature r <-> feature r for r in 10..14 on every pair
    pair_rows = {(0, 1): [(r, r) for r in range(10, 15)] + [(0, 0), (7, 7), (8, 7)],
                 (1, 2): [(r, r) for r in range(10, 15)] + [(0, 0)],
                 (0, 2): [(r, r) for r in range(10, 15)] + [(1, 0)]}
    # 0:0 - 1:0 - 2:0 - 0:1 is the Fig. 1 conflict; 0:7 and 0:8 both -> 1:7 is not one-to-one
    with h5py.File(matches, "w") as fd:
        for (i, j), rows in pair_rows.items():
            a, b = NAMES[i], NAMES[j]
            if pairs_swapped:
                a, b, rows = b, a, [(s, r) for r, s in rows]
            m0 = np.full(M, -1, dtype=np.int16)
            for r, s in rows:
                m0[r] = s
            g = fd.create_group(names_to_pair(a, b, "_" if old_keys else "/"))
            g.create_dataset("matches0", data=m0)
            g.create_dataset("matching_scores0", data=np.where(m0 >= 0, 0.9, 0).astype(np.float16))
    return feats, matches


def _matches0(path, a, b):
    with h5py.File(path, "r") as fd:
        return fd[names_to_pair(a, b)]["matches0"][()], fd[names_to_pair(a, b)]["matching_scores0"][()]




@pytest.mark.parametrize("swapped", [False, True])
def test_round_trip_cuts_the_conflict_and_the_duplicate(tmp_path, capsys, swapped):
    feats, matches = _write(tmp_path, pairs_swapped=swapped)
    digest = hashlib.sha256(matches.read_bytes()).hexdigest()
    contents = read_h5(feats, matches)
    # stored the other way round, b's row 7 can hold one of the two matches only
    dup = 0 if swapped else 1
    assert contents.names == sorted(NAMES) and len(contents.links) == 8 + 6 + 6 - (1 - dup)
    assert contents.not_one_to_one.sum() == dup
    out = tmp_path / "clean" / "matches-clean.h5"
    assert main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "conflictive sets: 1 before, 0 after" in printed
    assert hashlib.sha256(matches.read_bytes()).hexdigest() == digest  # input untouched
    cleaned = read_h5(feats, out)
    assert len(cleaned.links) == len(contents.links) - 1 - dup  # one resolution cut + duplicate
    assert not cleaned.not_one_to_one.any()
    # same layout and dtypes: hloc reads it as before
    with h5py.File(out, "r") as fd, h5py.File(matches, "r") as src:
        for key in cleaned.pair_key:
            assert fd[key]["matches0"].dtype == src[key]["matches0"].dtype
            cut = (src[key]["matches0"][()] >= 0) & (fd[key]["matches0"][()] < 0)
            assert (fd[key]["matching_scores0"][()][cut] == 0).all()
    side = read_run_links_csv(tmp_path / "clean" / "matches-clean.links.csv")
    assert sorted(side.reason[side.status == "deleted"].tolist()) == \
        ["not-one-to-one", "resolution"][1 - dup:]
    assert (tmp_path / "clean" / "matches-clean.rrd").is_file()


def test_baselines_beside_the_rule(tmp_path, capsys):
    """--baselines: every centralized baseline on the same matches, in the summary and printed;
    what each deleted is its own mask's count."""
    import json

    from pipeline.consistency.centralized import BASELINES

    feats, matches = _write(tmp_path)
    contents = read_h5(feats, matches)
    out, rep = tmp_path / "clean.h5", tmp_path / "s.json"
    assert main(["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
                 str(out), "--no-rerun", "--baselines", "--report", str(rep)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads(rep.read_text())
    links = contents.links.subset(~contents.not_one_to_one)
    assert sorted(summary["baselines"]) == sorted(BASELINES)
    for name, fn in BASELINES.items():
        mask = np.asarray(fn(contents.features_per_camera, links), dtype=bool)
        assert summary["baselines"][name]["deleted_links"] == int((~mask).sum()), name
        assert f"baseline {name}: " in printed


def test_pairs_file_limits_the_pairs_and_old_keys_are_read(tmp_path, capsys):
    feats, matches = _write(tmp_path, old_keys=True)
    pairs = tmp_path / "pairs.txt"
    pairs.write_text("a.jpg sub/b.jpg\nsub/b.jpg c.jpg\n")
    out = tmp_path / "o.h5"
    assert main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--pairs", str(pairs), "--out", str(out), "--no-rerun"]) == 0
    assert "2 image pairs" in capsys.readouterr().out
    assert not (tmp_path / "o.rrd").exists()
    assert len(read_h5(feats, out, pairs).links) == len(read_h5(feats, matches, pairs).links) - 1


@pytest.mark.parametrize("case, message", [
    ("pair-missing", "no matches stored for pair"),
    ("unknown-image", "has no keypoints"),
    ("not-h5", "not an HDF5 file"),
    ("out-is-input", "never modified"),
])
def test_bad_input_is_one_line(tmp_path, capsys, case, message):
    feats, matches = _write(tmp_path)
    argv = ["clean-h5", "--features", str(feats), "--matches", str(matches),
            "--out", str(tmp_path / "o.h5")]
    if case == "pair-missing":
        with h5py.File(matches, "a") as fd:
            del fd[names_to_pair("a.jpg", "c.jpg")]
        (tmp_path / "p.txt").write_text("a.jpg c.jpg\n")
        argv += ["--pairs", str(tmp_path / "p.txt")]
    elif case == "unknown-image":
        (tmp_path / "p.txt").write_text("a.jpg nope.jpg\n")
        argv += ["--pairs", str(tmp_path / "p.txt")]
    elif case == "not-h5":
        matches.write_text("hello")
    else:
        argv[-1] = str(matches)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_existing_output_needs_overwrite(tmp_path, capsys):
    feats, matches = _write(tmp_path)
    out = tmp_path / "o.h5"
    argv = ["clean-h5", "--features", str(feats), "--matches", str(matches), "--out", str(out)]
    out.write_bytes(b"keep me")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "already exists; pass --overwrite" in err and err.count("\n") == 1
    assert out.read_bytes() == b"keep me"
    assert main(argv + ["--overwrite"]) == 0
    assert out.read_bytes() != b"keep me"


def test_no_rerun_beside_an_earlier_recording_warns_that_it_is_stale(tmp_path, capsys):
    """--overwrite --no-rerun replaced OUT.h5 and OUT.links.csv and left the OUT.rrd of the
    run before beside them, named as this result's recording, without a word."""
    feats, matches = _write(tmp_path)
    out = tmp_path / "o.h5"
    argv = ["clean-h5", "--features", str(feats), "--matches", str(matches), "--out", str(out)]
    assert main(argv + ["--no-rerun"]) == 0
    assert "not this run's recording" not in capsys.readouterr().err  # no OUT.rrd: no word
    assert main(argv + ["--overwrite"]) == 0
    rrd = tmp_path / "o.rrd"
    recording = rrd.read_bytes()
    capsys.readouterr()
    assert main(argv + ["--overwrite", "--no-rerun"]) == 0
    err = capsys.readouterr().err
    assert f"warning: {str(rrd)!r} beside {str(out)!r} is not this run's recording" in err
    assert rrd.read_bytes() == recording  # warned, not removed


def test_the_rule_is_the_one_asked_for(tmp_path):
    """clean-h5 ran DEFAULT_LINKS_RESOLUTION whatever the user wanted; --resolution now picks
    the rule, named in the summary, and each rule leaves the matches conflict-free."""
    from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION

    feats, matches = _write(tmp_path)
    seen = {}
    for rule in ("paper", "sync"):
        report = tmp_path / f"{rule}.json"
        assert main(["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
                     str(tmp_path / f"{rule}.h5"), "--resolution", rule, "--no-rerun",
                     "--report", str(report)]) == 0
        s = json.loads(report.read_text())
        assert s["resolution"]["resolution"] == rule and s["after"]["conflictive_sets"] == 0
        seen[rule] = s
    assert DEFAULT_LINKS_RESOLUTION == "sync"
    default = tmp_path / "default.json"
    assert main(["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
                 str(tmp_path / "d.h5"), "--no-rerun", "--report", str(default)]) == 0
    assert json.loads(default.read_text())["resolution"]["resolution"] == "sync"
