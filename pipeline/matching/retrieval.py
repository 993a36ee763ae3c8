"""Image similarity from local features, to choose which images to match (``--graph knn:K``).

Unordered photo collections carry no information in their file names, so "the ``K``
nearest images" must come from the images themselves. Each image gets one global
descriptor, a VLAD vector (Jégou et al., "Aggregating local descriptors into a compact image
representation", CVPR 2010) built from the local descriptors the features stage already
computed:

1. a vocabulary of ``k`` visual words: k-means (``scipy.cluster.vq.kmeans2``, started from
   sampled descriptors, fixed seed) on a deterministic sample of the descriptors of all images,
   the images taken in the order of their descriptors' content digests (:func:`content_order`),
   so that neither file names nor the order of the cameras moves the vocabulary,
2. per image, the sum of the residuals ``d - c_w`` of its descriptors to their nearest word
   ``c_w``: a ``(k, D)`` array,
3. intra-normalisation (each word's residual sum to unit length; Arandjelović & Zisserman,
   "All about VLAD", CVPR 2013), signed square root, then L2 over the whole vector,
4. similarity of two images = dot product of their vectors (cosine, in ``[-1, 1]``).

``knn_edges`` then lets every image pick its ``K`` most similar images; an edge is kept
where either image picked the other; equal similarities go to the image first in content order.
Renaming or reordering the images therefore permutes the graph and changes nothing else. Interpretation for the papers' model: the comm graph is
an input of Aragüés et al. (Sec. II); here it is chosen once, before matching, from what each
robot could share cheaply (one global vector per robot), and never changes afterwards.
Binary descriptors (ORB, AKAZE) are unpacked to 0/1 bits and treated as real vectors.
"""

from __future__ import annotations

import hashlib
import warnings

import numpy as np

from pipeline.errors import InputError
from pipeline.types import Features

__all__ = ["content_order", "vocabulary", "vlad", "similarity", "knn_edges", "DEFAULT_WORDS"]

#: visual words of the vocabulary (fewer when the images hold fewer descriptors)
DEFAULT_WORDS = 64
#: descriptors drawn per image to train the vocabulary
SAMPLE_PER_IMAGE = 1000


def _as_real(descriptors: np.ndarray) -> np.ndarray:
    """``(N, D')`` float32: float descriptors as they are, binary ones unpacked to 0/1 bits."""
    d = np.asarray(descriptors)
    if d.dtype == np.uint8:
        return np.unpackbits(d, axis=1).astype(np.float32)
    return d.astype(np.float32, copy=False)


def content_order(features: list[Features]) -> np.ndarray:
    """Indices of ``features`` sorted by the SHA-256 digest of each image's descriptors.

    The order depends on what the images hold, never on their names or their camera index
    (two images with identical descriptors keep their relative order).

    Returns
    -------
    order : ndarray, (n,) int64 — a permutation of ``range(n)``
    """
    digests = [hashlib.sha256(np.ascontiguousarray(f.descriptors).tobytes()).digest()
               for f in features]
    return np.array(sorted(range(len(features)), key=lambda k: digests[k]), dtype=np.int64)


def vocabulary(features: list[Features], words: int = DEFAULT_WORDS, seed: int = 0,
               sample_per_image: int = SAMPLE_PER_IMAGE) -> np.ndarray:
    """k-means visual words from a sample of every image's descriptors.

    Parameters
    ----------
    features : list[Features], (n,)
    words : int — vocabulary size ``k`` (capped by the number of sampled descriptors)
    seed : int — k-means seed: the vocabulary is repeatable
    sample_per_image : int — at most this many descriptors of each image (evenly spaced)

    The sample is stacked in :func:`content_order`, so the k-means start (sampled points,
    ``seed``) and hence the words do not depend on the order of ``features``.

    Returns
    -------
    centres : ndarray, (k, D') float32 — ``k = 0`` when no image has descriptors
    """
    from scipy.cluster.vq import kmeans2

    parts = []
    for k in content_order(features):
        d = _as_real(features[k].descriptors)
        if len(d) > sample_per_image:
            d = d[np.linspace(0, len(d) - 1, sample_per_image).astype(np.int64)]
        parts.append(d)
    sample = np.concatenate(parts) if parts else np.zeros((0, 0), np.float32)
    if len(sample) == 0:
        return np.zeros((0, sample.shape[1] if sample.ndim == 2 else 0), np.float32)
    k = int(min(words, len(sample)))
    with warnings.catch_warnings():
        # an empty cluster is harmless here: that word just never receives a residual
        warnings.simplefilter("ignore", UserWarning)
        centres, _ = kmeans2(sample.astype(np.float64), k, minit="points", seed=seed)
    return centres.astype(np.float32)


def _nearest_word(d: np.ndarray, centres: np.ndarray) -> np.ndarray:
    sq = (d * d).sum(1)[:, None] + (centres * centres).sum(1)[None, :] - 2.0 * d @ centres.T
    return sq.argmin(axis=1)


def vlad(features: Features, centres: np.ndarray) -> np.ndarray:
    """The normalised VLAD vector of one image (module notes, steps 2-3).

    Parameters
    ----------
    features : Features — ``N`` local descriptors
    centres : ndarray, (k, D') — from :func:`vocabulary`

    Returns
    -------
    v : ndarray, (k * D',) float32, unit length (all zeros for an image without features)
    """
    k, dim = centres.shape
    d = _as_real(features.descriptors)
    out = np.zeros((k, dim), np.float32)
    if len(d) == 0 or k == 0:
        return out.reshape(-1)
    w = _nearest_word(d, centres)
    np.add.at(out, w, d - centres[w])
    norms = np.linalg.norm(out, axis=1, keepdims=True)
    out = np.divide(out, norms, out=np.zeros_like(out), where=norms > 0)
    out = np.sign(out) * np.sqrt(np.abs(out))
    total = float(np.linalg.norm(out))
    return (out / total if total > 0 else out).reshape(-1)


def similarity(features: list[Features], words: int = DEFAULT_WORDS, seed: int = 0) -> np.ndarray:
    """Pairwise image similarity ``S (n, n)`` float64, cosine of the VLAD vectors.

    ``S`` is symmetric; the diagonal is 1 for an image with features, 0 without.
    """
    centres = vocabulary(features, words, seed)
    v = np.stack([vlad(f, centres) for f in features]) if features else np.zeros((0, 0))
    return (v @ v.T).astype(np.float64)


def knn_edges(features: list[Features], k: int, words: int = DEFAULT_WORDS,
              seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Every image linked to its ``k`` most similar images (union of the choices).

    Parameters
    ----------
    features : list[Features], (n,) — one per image, in camera order
    k : int >= 1 — neighbours each image picks; ``k >= n - 1`` gives the complete graph
    words, seed : see :func:`vocabulary`

    Returns
    -------
    edges : ndarray, (E, 2) int64, ``i < j``, sorted, no duplicates
    S : ndarray, (n, n) float64 — the similarity the choice was made on

    Raises
    ------
    InputError
        Fewer than two images, or ``k < 1``.

    Notes
    -----
    Ties go to the image first in :func:`content_order`, so the graph is repeatable and the
    same for any order of the images. An image without features (a blank one) is picked last,
    after every image with features: its similarity, 0, would otherwise outrank the cosines
    of images that overlap, which are often negative (the vocabulary is drawn from these
    very images), and every image would pick it and match nothing. Each image picks
    ``min(k, n - 1)`` neighbours: ``n * min(k, n-1) / 2`` to ``n * min(k, n-1)`` edges.
    """
    n = len(features)
    if n < 2:
        raise InputError(f"knn graph: at least two images are needed, got {n}")
    if isinstance(k, bool) or int(k) != k or k < 1:
        raise InputError(f"knn graph: K must be a positive integer, got {k!r}")
    k = int(min(k, n - 1))
    S = similarity(features, words, seed)
    # rounded: a product of the same two vectors may differ in its last bit with their rows'
    # places in the matrix, which must not decide a near tie
    key = -np.round(S, 9)
    # below any cosine (>= -1): an image without features is nobody's choice while another is
    key[:, [len(f) == 0 for f in features]] = 2.0
    np.fill_diagonal(key, np.inf)
    # sort on (-similarity, content rank): equal similarities go to the image first in
    # content order, whatever the camera indices
    rank = np.empty(n, dtype=np.int64)
    rank[content_order(features)] = np.arange(n)
    nearest = np.lexsort((np.broadcast_to(rank, (n, n)), key), axis=1)[:, :k]
    e = np.stack([np.repeat(np.arange(n), k), nearest.reshape(-1)], axis=1)
    e = np.unique(np.sort(e, axis=1), axis=0).astype(np.int64)
    return e, S
