"""clean-h5 reads hloc's matching_scores0 as the links' quality: a distance (higher = worse)
or a score above 1 is warned of, as resolve warns of its quality column."""

import json

import h5py
import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.inputs.hloc import names_to_pair

NAMES = ["a.jpg", "b.jpg", "c.jpg"]
M = 40


def _write(d, good_score, wrong_score):
    """Three images: keypoints 0..19 one track through all three (every link confirmed by its
    triangle); 20..29 of a and b each matched into c, and a to b one keypoint off (no link of
    them closes a triangle: all refuted). Scores ``good_score`` on the first, ``wrong_score``
    on the second, each spread a little."""
    feats, matches = d / "features.h5", d / "matches.h5"
    rng = np.random.default_rng(0)
    with h5py.File(feats, "w") as fd:
        for name in NAMES:
            fd.create_group(name).create_dataset(
                "keypoints", data=rng.uniform(0, 300, (M, 2)).astype(np.float32))
    track = [(r, r) for r in range(20)]
    off = [(r, r) for r in range(20, 30)]
    rot = [(r, 20 + (r - 19) % 10) for r in range(20, 30)]
    pairs = {(0, 1): (track, rot), (0, 2): (track, off), (1, 2): (track, off)}
    with h5py.File(matches, "w") as fd:
        for (i, j), (good, wrong) in pairs.items():
            m0 = np.full(M, -1, np.int32)
            s0 = np.zeros(M, np.float32)
            for rows, score in ((good, good_score), (wrong, wrong_score)):
                for k, (r, s) in enumerate(rows):
                    m0[r] = s
                    s0[r] = score * (1 - 0.01 * k)
            g = fd.create_group(names_to_pair(NAMES[i], NAMES[j]))
            g.create_dataset("matches0", data=m0)
            g.create_dataset("matching_scores0", data=s0)
    return feats, matches


@pytest.mark.parametrize("good, wrong, needles, absent", [
    (0.1, 0.8, ["quality looks reversed"], ["above 1"]),           # a distance in [0, 1]
    (80.0, 10.0, ["qualities are above 1"], ["reversed"]),          # a similarity of 0..100
    (0.9, 0.2, [], ["reversed", "above 1"]),                        # hloc's own scores
], ids=["distance", "scale-100", "similarity"])
def test_scores_that_are_no_similarity_in_0_1_are_warned(tmp_path, capsys, good, wrong,
                                                         needles, absent):
    feats, matches = _write(tmp_path, good, wrong)
    report = tmp_path / "summary.json"
    assert main(["clean-h5", "--features", str(feats), "--matches", str(matches),
                 "--out", str(tmp_path / "out.h5"), "--no-rerun", "--report", str(report)]) == 0
    err = capsys.readouterr().err
    warned = [w for w in err.splitlines() if w.startswith("warning:")]
    for needle in needles:
        assert sum(needle in w for w in warned) == 1, err
    assert not any(a in w for a in absent for w in warned), err
    s = json.loads(report.read_text())
    assert s["quality_evidence"]["confirmed"] == 60 and s["quality_evidence"]["refuted"] == 30
    assert len(s.get("warnings", [])) == len(needles)
