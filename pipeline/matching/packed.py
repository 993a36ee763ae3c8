"""Features in compact form for the wire: what a robot sends a neighbour to match against.

Aragüés et al. (Sec. II, V-B) match each pair of neighbours locally, so the feature exchange
is the price of the association in a team with limited communications; it is most of what a
team sends. This module packs a robot's features so that the receiver rebuilds exactly the
arrays the sender matches with:

* **SIFT** (OpenCV): the descriptor is computed as float32 but every value is already an
  integer in 0..255 (OpenCV rounds each bin to a byte and stores it as a float), so it
  travels as uint8 with scale 1 and is restored exactly: 4x fewer bytes, the receiver's
  matches identical. A float descriptor that is not integral in 0..255 (e.g. SURF, absent
  from this build's OpenCV) travels as float32, unchanged.
* **RootSIFT** (:func:`pipeline.matching.features.root_sift`): the sender sends the SIFT
  descriptor it was computed from (uint8, as above) with a flag; the receiver applies
  ``root_sift`` itself. ``root_sift`` is one deterministic numpy expression, so the receiver's
  RootSIFT equals the sender's bit for bit (interpretation: sending the square roots
  quantised to a byte would change ratio-test decisions near the threshold; sending their
  source changes none).
* **Binary** descriptors (ORB, AKAZE) are uint8 already: as is.
* **Keypoints** stay float32 (8 bytes a feature next to the descriptor's 128): quantising
  them would move the epipolar RANSAC's inputs and so its decisions.

The byte-level compression of whole packets is the wire's (:mod:`pipeline.transport.wire`).
"""

from __future__ import annotations

import numpy as np

from pipeline.matching.features import root_sift

__all__ = ["pack_features", "unpack_features", "matching_descriptors", "extract_raw"]


def extract_raw(view, opts: dict, merge_radius: float):
    """A robot's own features as it sends them: extracted without RootSIFT, and whether it
    matches with RootSIFT of them (:func:`matching_descriptors`; COLMAP's SIFT is L1-rooted
    already, so RootSIFT applies to OpenCV's SIFT only, as in
    :func:`pipeline.matching.features.extract`). ``opts``: a robot's options
    (:data:`pipeline.team.teamfile.DEFAULT_OPTIONS`: ``features``, ``max_features`` — ``None``
    scales with the image —, ``contrast_threshold``, ``rootsift``, ``budget_after_merge``).
    Returns ``(raw Features, rootsift)``."""
    from pipeline.matching.features import extract

    budget = opts.get("max_features")
    raw = extract(view, opts["features"], None if budget is None else int(budget),
                  float(merge_radius), contrast_threshold=opts.get("contrast_threshold"),
                  rootsift=False, budget_after_merge=bool(opts.get("budget_after_merge", False)))
    return raw, bool(opts.get("rootsift", False)) and opts["features"] != "colmap-sift"


def matching_descriptors(raw: np.ndarray, rootsift: bool) -> np.ndarray:
    """The descriptors a robot matches with, from the extractor's ``raw`` ones: RootSIFT of
    a float descriptor when asked (as :func:`pipeline.matching.features.extract` with
    ``rootsift=True`` computes it), else ``raw`` unchanged."""
    if rootsift and raw.dtype == np.float32:
        return root_sift(raw)
    return raw


def pack_features(keypoints: np.ndarray, raw_descriptors: np.ndarray, rootsift: bool) -> dict:
    """The arrays to send: keypoints and descriptors in compact form.

    Parameters
    ----------
    keypoints : ndarray, (N, 2) float32
    raw_descriptors : ndarray, (N, D) — as the extractor returned them *before* RootSIFT
        (``extract(..., rootsift=False)``)
    rootsift : bool — the receiver matches with :func:`matching_descriptors` of them

    Returns
    -------
    dict of arrays: ``keypoints``, ``descriptors`` (uint8 or float32), ``descriptor_form``
    (uint8 ``[float_from_byte, rootsift]``)
    """
    d = np.asarray(raw_descriptors)
    as_byte = False
    if d.dtype == np.float32 and d.size:
        as_byte = bool(np.all((d >= 0) & (d <= 255) & (d == np.round(d))))
    elif d.dtype == np.float32:
        as_byte = True  # no feature: nothing to lose
    root = bool(rootsift and d.dtype == np.float32)
    return {"keypoints": np.ascontiguousarray(keypoints, dtype=np.float32),
            "descriptors": d.astype(np.uint8) if as_byte else d,
            "descriptor_form": np.array([as_byte, root], np.uint8)}


def unpack_features(payload: dict) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`pack_features`: ``(keypoints, descriptors to match with)``, equal to
    the sender's own (``matching_descriptors(raw, rootsift)``). A payload without
    ``descriptor_form`` holds the descriptors to match with as they are."""
    d = payload["descriptors"]
    if "descriptor_form" not in payload:
        return payload["keypoints"].reshape(-1, 2), d
    as_byte, root = (bool(v) for v in payload["descriptor_form"][:2])
    if as_byte:
        d = d.astype(np.float32)
    return payload["keypoints"].reshape(-1, 2), matching_descriptors(d, root)
