"""The names of the matching's variants (feature methods, pair matchers) and the feature budget
a run may ask for.

One list each, in a module that imports nothing heavy, so that a team file can be checked
(:mod:`pipeline.team.teamfile`) without loading OpenCV. The variants themselves live where
they run: the detectors in :data:`pipeline.matching.features.DETECTORS` (one entry per name
below), the matchers in :func:`pipeline.matching.pairs.match_pair`.
"""

from __future__ import annotations

from pipeline.errors import InputError

__all__ = ["FEATURE_METHODS", "COLMAP_SIFT", "MATCHERS", "MIN_FEATURES", "MAX_FEATURES",
           "max_features"]

#: COLMAP's SIFT (pycolmap, :mod:`pipeline.colmap.sift`) rather than OpenCV's
COLMAP_SIFT = "colmap-sift"

#: feature methods (``surf`` needs an OpenCV build with the non-free algorithms: whether this
#: machine's offers it is :func:`pipeline.matching.features.available_methods`)
FEATURE_METHODS = ("sift", "orb", "akaze", "surf", COLMAP_SIFT)

#: pair matchers: OpenCV + numpy (:func:`pipeline.matching.pairs.mutual_ratio_matches`,
#: :func:`pipeline.matching.pairs.epipolar_filter`) or COLMAP's
#: (:func:`pipeline.colmap.sift.match_pairs`)
MATCHERS = ("opencv", "colmap")

#: Fewest features per image a run accepts (an epipolar RANSAC needs 7 or 8 matches).
MIN_FEATURES = 8

#: Most features per image a run accepts: over a hundred times COLMAP's default of 8192, and
#: far below where OpenCV's detectors fail to allocate (ORB: ``std::bad_alloc`` at 2**31 - 1)
#: or overflow (beyond 2**31: a traceback).
MAX_FEATURES = 1_000_000


def max_features(value, flag: str = "--max-features", auto: str = "'auto'") -> int:
    """A count of features per image, ``MIN_FEATURES .. MAX_FEATURES``, checked alike on the
    command line and in a team file; ``auto`` is how the source spells a count scaled with
    each image (``null`` in a team file)."""
    try:
        v = int(str(value).strip())
    except ValueError:
        raise InputError(f"{flag} {value!r}: expected a number of features or {auto}") from None
    if v < MIN_FEATURES:
        raise InputError(f"{flag} {v}: at least {MIN_FEATURES} are needed")
    if v > MAX_FEATURES:
        raise InputError(f"{flag} {v}: at most {MAX_FEATURES} per image; give a smaller count "
                         f"(e.g. 2000) or {auto} for photos")
    return v
