"""The command-line options several commands share: one definition, one check."""

import argparse

import pytest

from pipeline.commands.options import (
    add_feature_options,
    add_scene_options,
    feature_options,
    parse_size,
)
from pipeline.errors import InputError


def _parse(argv):
    p = argparse.ArgumentParser()
    add_feature_options(p)
    add_scene_options(p)
    return p.parse_args(argv)


def test_defaults_and_case():
    args = _parse([])
    assert feature_options(args) == ("sift", 2000)
    assert (args.seed, parse_size(args.size)) == (0, (640, 480))
    assert feature_options(_parse(["--features", "ORB", "--max-features", "8"])) == ("orb", 8)


@pytest.mark.parametrize("argv,match", [
    (["--features", "brief"], "--features 'brief': choose one of sift, orb, akaze"),
    (["--max-features", "7"], "--max-features 7: at least 8"),
])
def test_bad_feature_options(argv, match):
    with pytest.raises(InputError, match=match):
        feature_options(_parse(argv))


@pytest.mark.parametrize("text,match", [("640", "expected WIDTHxHEIGHT"),
                                        ("63x480", "at least 64x48")])
def test_bad_size(text, match):
    with pytest.raises(InputError, match=match):
        parse_size(text)


def test_photo_options_default_to_a_budget_scaled_with_the_image():
    p = argparse.ArgumentParser()
    add_feature_options(p, photos=True)
    assert feature_options(p.parse_args([])) == ("sift", None)
    assert feature_options(p.parse_args(["--max-features", "4096"])) == ("sift", 4096)
    with pytest.raises(InputError, match="expected a number of features or 'auto'"):
        feature_options(p.parse_args(["--max-features", "many"]))
