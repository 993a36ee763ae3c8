"""Image similarity for ``knn:K`` graphs: similar images pick each other, whatever their order."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.matching.retrieval import content_order, knn_edges, similarity, vlad, vocabulary
from pipeline.types import Features


def _feats(desc: np.ndarray) -> Features:
    n = len(desc)
    return Features(np.zeros((n, 2), np.float32), desc, np.ones(n, np.float32), "sift")


def _scenes(rng, groups: list[int], per_image: int = 300, dim: int = 32):
    """Images of a few 'scenes': each image sees a random subset of its scene's descriptors,
    with noise; the scenes share no descriptors."""
    bases = {g: rng.random((600, dim)).astype(np.float32) for g in set(groups)}
    out = []
    for g in groups:
        pick = rng.choice(600, per_image, replace=False)
        out.append(_feats(bases[g][pick] + 0.02 * rng.standard_normal((per_image, dim)).astype(np.float32)))
    return out


def test_images_of_one_scene_pick_each_other_in_any_order():
    rng = np.random.default_rng(1)
    groups = [0, 1, 2, 0, 1, 2, 0, 1, 2]  # name order interleaves the scenes
    edges, S = knn_edges(_scenes(rng, groups), k=2)
    g = np.array(groups)
    assert len(edges) >= 9
    assert (g[edges[:, 0]] == g[edges[:, 1]]).all()
    assert np.allclose(S, S.T)


def test_k_at_least_n_minus_one_is_the_complete_graph():
    rng = np.random.default_rng(2)
    edges, _ = knn_edges(_scenes(rng, [0, 0, 1, 1]), k=7)
    assert edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]


def test_images_without_features_still_get_k_neighbours_repeatably():
    rng = np.random.default_rng(3)
    feats = _scenes(rng, [0, 0, 1]) + [_feats(np.zeros((0, 32), np.float32))]
    e1, S = knn_edges(feats, k=1)
    e2, _ = knn_edges(feats, k=1)
    assert e1.tolist() == e2.tolist()
    assert 3 in e1 and S[3, 3] == 0.0


def test_vlad_is_unit_length_and_binary_descriptors_work():
    rng = np.random.default_rng(4)
    feats = [Features(np.zeros((50, 2), np.float32), rng.integers(0, 256, (50, 32), dtype=np.uint8),
                      np.ones(50, np.float32), "orb") for _ in range(3)]
    c = vocabulary(feats, words=8)
    assert c.shape == (8, 256)
    assert np.isclose(np.linalg.norm(vlad(feats[0], c)), 1.0, atol=1e-5)
    assert similarity(feats).shape == (3, 3)


@pytest.mark.parametrize("k", [0, -1, 1.5, True])
def test_bad_k(k):
    rng = np.random.default_rng(5)
    with pytest.raises(InputError, match="K must be a positive integer"):
        knn_edges(_scenes(rng, [0, 1]), k=k)


def test_one_image_is_an_error():
    with pytest.raises(InputError, match="at least two images"):
        knn_edges([_feats(np.ones((3, 32), np.float32))], k=1)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**16), k=st.integers(1, 4))
def test_reordering_the_images_permutes_the_graph_and_changes_nothing_else(seed, k):
    # the k-means start and the ties come from the images' content, never from their order
    rng = np.random.default_rng(seed)
    feats = _scenes(rng, [0, 1, 0, 1, 2, 2, 0], per_image=80, dim=16)
    feats.append(_feats(np.zeros((0, 16), np.float32)))  # ties: an image without features
    perm = rng.permutation(len(feats))
    edges, S = knn_edges(feats, k, words=8)
    edges_p, S_p = knn_edges([feats[p] for p in perm], k, words=8)
    back = np.sort(perm[edges_p], axis=1)
    assert sorted(map(tuple, back.tolist())) == sorted(map(tuple, edges.tolist()))
    assert np.allclose(S_p, S[np.ix_(perm, perm)], atol=1e-6)


def test_content_order_ignores_the_order_of_the_images():
    rng = np.random.default_rng(3)
    feats = _scenes(rng, [0, 1, 2, 0])
    order = content_order(feats)
    assert sorted(order.tolist()) == [0, 1, 2, 3]
    rev = content_order(feats[::-1])
    assert [3 - k for k in rev.tolist()] == order.tolist()
