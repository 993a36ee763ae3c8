"""A blank image (no feature) in a knn graph: the other images still pick each other."""

import numpy as np

from pipeline.matching.retrieval import knn_edges, similarity
from pipeline.types import Features


def _features(n: int, rng) -> Features:
    return Features(rng.random((n, 2), dtype=np.float32) * 100,
                    rng.random((n, 128), dtype=np.float32), np.ones(n, np.float32), "sift")


def test_an_image_without_features_is_picked_last():
    rng = np.random.default_rng(0)
    feats = [_features(80, rng), _features(0, rng), _features(80, rng), _features(80, rng)]
    S = similarity(feats)
    real = [0, 2, 3]
    # the cosines of the images with features are negative here, below the blank one's 0
    assert (S[np.ix_(real, real)][~np.eye(3, dtype=bool)] < 0).all()
    edges, _ = knn_edges(feats, 1)
    # each image with features picks another one with features; the blank one picks one too
    picked = {tuple(e) for e in edges.tolist()}
    for i in real:
        assert any(i in e and 1 not in e for e in picked), (i, picked)
    assert sum(1 in e for e in picked) == 1
    # with K covering every image, the blank one is still in the graph
    full, _ = knn_edges(feats, 3)
    assert len(full) == 6
