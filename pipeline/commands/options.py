"""Command-line options shared by several commands, each defined once with one check.

``--features`` and ``--max-features`` (the feature stage, :mod:`pipeline.features`),
``--seed`` and ``--size`` (the rendered formations of :mod:`data_synth`).
"""

from __future__ import annotations

import argparse

from pipeline.errors import InputError
from pipeline.validate import render_size

__all__ = ["MIN_FEATURES", "add_feature_options", "add_scene_options", "feature_options",
           "parse_size"]

#: Fewest features per image a run accepts (an epipolar RANSAC needs 7 or 8 matches).
MIN_FEATURES = 8


def add_feature_options(p: argparse.ArgumentParser) -> None:
    """``--features`` and ``--max-features``; check them with :func:`feature_options`."""
    from pipeline.features import METHODS

    p.add_argument("--features", default="sift",
                   help=f"feature method: {'|'.join(METHODS)} (default sift; surf only where "
                        "the OpenCV build has non-free algorithms)")
    p.add_argument("--max-features", type=int, default=2000,
                   help="features per image (default 2000)")


def add_scene_options(p: argparse.ArgumentParser) -> None:
    """``--seed`` and ``--size WIDTHxHEIGHT`` of rendered formations; parse the size with
    :func:`parse_size`."""
    p.add_argument("--seed", type=int, default=0, help="scene and noise seed (default 0)")
    p.add_argument("--size", default="640x480", help="image size WIDTHxHEIGHT (default 640x480)")


def feature_options(args) -> tuple[str, int]:
    """The checked ``(method, max_features)`` of :func:`add_feature_options`' options.

    Raises
    ------
    InputError
        An unknown method, one this OpenCV build lacks, or fewer than :data:`MIN_FEATURES`.
    """
    from pipeline.features import METHODS, check_method

    method = str(args.features).lower()
    if method not in METHODS:
        raise InputError(f"--features {args.features!r}: choose one of {', '.join(METHODS)} "
                         f"(unknown feature method {args.features!r})")
    check_method(method)
    if args.max_features < MIN_FEATURES:
        raise InputError(f"--max-features {args.max_features}: at least {MIN_FEATURES} are "
                         "needed")
    return method, int(args.max_features)


def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` → ``(640, 480)``; InputError on anything else.

    >>> parse_size("320x240")
    (320, 240)
    """
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    return render_size(w, h, text)
