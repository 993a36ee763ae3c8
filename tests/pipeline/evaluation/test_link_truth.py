import sys
import types

import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.evaluation.links import (
    MissingLinks,
    link_counts,
    link_truth,
    missing_links,
    missing_links_per_edge,
)
from pipeline.types import Features, Links


def feats(xy):
    xy = np.asarray(xy, np.float32).reshape(-1, 2)
    return Features(xy, np.zeros((len(xy), 128), np.float32), np.ones(len(xy), np.float32), "sift")


@pytest.fixture
def identity_truth(monkeypatch):
    """Ground truth of cameras that all see the same image: same pixel = same point."""

    def good_links(formation, i, xy_i, j, xy_j, tol_px=2.0):
        return np.linalg.norm(np.asarray(xy_i) - np.asarray(xy_j), axis=1) <= tol_px

    def true_pairs(formation, i, xy_i, j, xy_j, tol_px=2.0):
        d = np.linalg.norm(np.asarray(xy_i)[:, None] - np.asarray(xy_j)[None], axis=2)
        r, s = np.nonzero(d <= tol_px)
        return np.stack([r, s], axis=1)

    fake = types.ModuleType("data_synth.ground_truth")
    fake.good_links, fake.true_pairs = good_links, true_pairs
    monkeypatch.setitem(sys.modules, "data_synth.ground_truth", fake)
    return types.SimpleNamespace(views=[None, None, None])


def three_cameras():
    f = [feats([[0, 0], [10, 10], [20, 20]]), feats([[0, 1], [20, 20], [50, 50]]),
         feats([[10, 10], [0, 0]])]
    # 0-1: (0,0) good, (1,2) spurious; 0-2: (0,1) good; 1-2: (1,0) spurious
    links = Links([0, 0, 0, 1], [0, 1, 0, 1], [1, 1, 2, 2], [0, 2, 1, 0])
    return f, links


def test_link_truth_hand_computed(identity_truth):
    f, links = three_cameras()
    np.testing.assert_array_equal(link_truth(identity_truth, f, links), [True, False, True, False])
    np.testing.assert_array_equal(link_truth(identity_truth, f, links, tol_px=0.5),
                                  [False, False, True, False])


def test_missing_links_only_on_comm_edges(identity_truth):
    f, links = three_cameras()
    # true pairs: 0-1 {(0,0), (2,1)}; 0-2 {(0,1), (1,0)}; 1-2 {(0,1)}
    np.testing.assert_array_equal(
        missing_links_per_edge(identity_truth, f, links, [[0, 1], [2, 0], [1, 2]]), [1, 1, 1])
    assert missing_links(identity_truth, f, links, [[0, 1]]) == 1
    assert missing_links(identity_truth, f, links, []) == 0


def test_one_missing_links_counter_scores_many_link_sets(identity_truth):
    f, links = three_cameras()
    edges = [[0, 1], [2, 0], [1, 2]]
    count = MissingLinks(identity_truth, f, edges)
    # each subset: its own missing links, whatever was scored before (the 0-1 pair (2,1)
    # and the 1-2 pair (0,1) are never linked; a dropped good link becomes missing)
    for keep, want in (([True, True, True, True], [1, 1, 1]), ([False, True, True, True], [2, 1, 1]),
                       ([True, True, False, False], [1, 2, 1]), ([True, True, True, True], [1, 1, 1])):
        np.testing.assert_array_equal(count.per_edge(links.subset(np.array(keep))), want)
        assert count(links.subset(np.array(keep))) == sum(want)
    with pytest.raises(InputError):
        count.per_edge(Links([0], [5], [1], [0]))  # a feature camera 0 does not have


def test_link_counts(identity_truth):
    f, links = three_cameras()
    c = link_counts(identity_truth, f, links, [[0, 1], [0, 2], [1, 2]])
    assert c == {"good_links": 2, "spurious_links": 2, "missing_links": 3, "precision": 0.5}


def test_no_links(identity_truth):
    f, _ = three_cameras()
    empty = Links.from_matches([])
    assert link_truth(identity_truth, f, empty).shape == (0,)
    assert missing_links(identity_truth, f, empty, [[0, 1]]) == 2


def test_link_counts_without_links_has_no_precision(identity_truth):
    # 0 of 0 links good is no precision (nan), not a precision of 0 or 1
    f, _ = three_cameras()
    c = link_counts(identity_truth, f, Links.from_matches([]), [[0, 1], [0, 2], [1, 2]])
    assert (c["good_links"], c["spurious_links"], c["missing_links"]) == (0, 0, 5)
    assert np.isnan(c["precision"])


def test_bad_inputs(identity_truth):
    f, links = three_cameras()
    with pytest.raises(InputError, match="2 feature sets for a formation of 3"):
        link_truth(identity_truth, f[:2], links)
    with pytest.raises(InputError, match="features"):
        link_truth(identity_truth, f, Links([0], [7], [1], [0]))
    with pytest.raises(InputError, match="unknown camera"):
        missing_links(identity_truth, f, links, [[0, 3]])


def test_with_rendered_formation():
    import data_synth
    from data_synth.ground_truth import true_pairs
    from pipeline.matching.features import extract_all

    f = data_synth.render("a", seed=0, size=(320, 240))
    fs = extract_all(f.views, "orb", 300)
    i, j = (int(v) for v in f.comm_edges[0])
    tp = true_pairs(f, i, fs[i].keypoints, j, fs[j].keypoints)
    assert len(tp) > 10
    exact = Links(np.full(len(tp), i), tp[:, 0], np.full(len(tp), j), tp[:, 1])
    assert link_truth(f, fs, exact).all()
    assert missing_links(f, fs, exact, [[i, j]]) == 0
    half = exact.subset(np.arange(len(tp)) % 2 == 0)
    assert missing_links(f, fs, half, [[i, j]]) == len(tp) - len(half)
    # a link shifted to a wrong partner is spurious
    wrong = Links([i], [tp[0, 0]], [j], [tp[1, 1]])
    assert not link_truth(f, fs, wrong).any()


def test_missing_links_of_camera_pairs_with_one_sum_are_told_apart(identity_truth):
    # four cameras see one point each; edges (0, 3) and (1, 2) add up to 3: the link of
    # (0, 3) does not stand for the true pair of (1, 2)
    formation = types.SimpleNamespace(views=[None] * 4)
    f = [feats([[0, 0]]) for _ in range(4)]
    links = Links([0], [0], [3], [0])
    np.testing.assert_array_equal(
        missing_links_per_edge(formation, f, links, [[0, 3], [1, 2]]), [0, 1])
    assert MissingLinks(formation, f, [[1, 2], [0, 3]])(links) == 1
