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


def test_photo_options_default_to_colmaps_sift_and_a_budget_scaled_with_the_image():
    p = argparse.ArgumentParser()
    add_feature_options(p, photos=True)
    assert feature_options(p.parse_args([])) == ("colmap-sift", None)
    assert feature_options(p.parse_args(["--max-features", "4096"])) == ("colmap-sift", 4096)
    assert feature_options(p.parse_args(["--features", "sift"])) == ("sift", None)
    q = argparse.ArgumentParser()
    add_feature_options(q)
    assert feature_options(q.parse_args([])) == ("sift", 2000)
    with pytest.raises(InputError, match="expected a number of features or 'auto'"):
        feature_options(p.parse_args(["--max-features", "many"]))


def test_one_default_resolution_everywhere_but_run_formations(tmp_path):
    # the Python API, the stage functions, every command that resolves, the configs, the
    # robot program and a hand-written TEAM.json all read DEFAULT_RESOLUTION from the
    # registry of rules; run-formations keeps the paper's rule; the jobs that receive links
    # only (resolve, clean-db, clean-h5, run-landmarks) read DEFAULT_LINKS_RESOLUTION
    import inspect
    import json

    from pipeline.__main__ import build_parser
    from pipeline.consistency import resolve_conflicts
    from pipeline.consistency.rules import (
        DEFAULT_LINKS_RESOLUTION,
        DEFAULT_RESOLUTION,
        rule_names,
    )
    from pipeline.consistency.termination import run_consistency_locally
    from pipeline.runs.clean_db import clean_database
    from pipeline.runs.formation import FormationConfig
    from pipeline.runs.images import ImagesConfig
    from pipeline.runs.resolve import resolve_file
    from pipeline.stages import clean_association, consistency_stage
    from pipeline.team.assemble import team_options
    from pipeline.team.robot import robot_resolution
    from pipeline.team.teamfile import DEFAULT_OPTIONS, load_team
    from pipeline.types import Links

    assert DEFAULT_RESOLUTION == "evidence" and DEFAULT_RESOLUTION in rule_names()
    assert DEFAULT_LINKS_RESOLUTION == "sync" and DEFAULT_LINKS_RESOLUTION in rule_names()
    for fn in (resolve_conflicts, consistency_stage, clean_association,
               run_consistency_locally, team_options):
        assert inspect.signature(fn).parameters["resolution"].default == DEFAULT_RESOLUTION, fn
    for fn in (clean_database, resolve_file):
        assert inspect.signature(fn).parameters["resolution"].default == \
            DEFAULT_LINKS_RESOLUTION, fn
    assert FormationConfig().resolution == DEFAULT_RESOLUTION
    assert ImagesConfig("photos", "ring").resolution == DEFAULT_RESOLUTION
    assert DEFAULT_OPTIONS["resolution"] == DEFAULT_RESOLUTION
    parser = build_parser()
    for command, argv, want in (
            ("run-formation", [], DEFAULT_RESOLUTION),
            ("run-images", ["DIR", "--graph", "ring"], DEFAULT_RESOLUTION),
            ("resolve", ["--links", "a", "--out", "b"], DEFAULT_LINKS_RESOLUTION),
            ("clean-db", ["in.db", "--out", "out.db"], DEFAULT_LINKS_RESOLUTION),
            ("run-formations", [], "paper"),
            ("run-landmarks", ["DIR"], DEFAULT_LINKS_RESOLUTION)):
        args = parser.parse_args([command, *argv])
        assert args.resolution == want, command
    team_file = tmp_path / "TEAM.json"
    team_file.write_text(json.dumps({
        "version": 1, "name": "two", "comm_edges": [[0, 1]],
        "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7447"},
                   {"id": 1, "endpoint": "tcp/127.0.0.1:7448"}],
        "data": {"kind": "formation", "formation": "line", "robots": 2, "seed": 0}}))
    assert robot_resolution(load_team(team_file).options_for(0), lossy=False) == DEFAULT_RESOLUTION
    # and the default is what runs: the paper's Fig. 1, its weakest link cut by the evidence
    links = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0], [0.8, 0.8, 0.2, 0.8])
    res = resolve_conflicts([1, 1, 1, 2], None, links)
    assert res.stats["resolution"] == "evidence" and res.deleted.tolist() == [0, 0, 1, 0]


def test_each_commands_help_names_only_its_own_options():
    """run-formations --help told of --drop-prob, --crash, ... (beside --resolution) and
    run-formation's --steps (beside --merge-radius), options it does not have; a flag after
    another command's name ('as run-formation --steps N') is that command's."""
    import re

    from pipeline.__main__ import build_parser

    sub = next(a for a in build_parser()._actions if a.choices and isinstance(a.choices, dict))
    commands = set(sub.choices)
    foreign = []
    for name, parser in sub.choices.items():
        own = {s for a in parser._actions for s in a.option_strings}
        for action in parser._actions:
            for m in re.finditer(r"(\S+) (--[a-z][a-z0-9-]*)|(--[a-z][a-z0-9-]*)", action.help or ""):
                flag = m.group(2) or m.group(3)
                if flag not in own and m.group(1) not in commands:
                    foreign.append(f"{name} {action.option_strings}: {flag}")
    assert foreign == []


@pytest.mark.parametrize("command,colmap_sift_radius", [
    ("run-formation", 2.0), ("run-formations", 2.0), ("run-images", 0.5)])
def test_merge_radius_help_states_what_colmap_sift_gets(command, colmap_sift_radius):
    """run-formation's and run-formations' --help said "0.5 px with colmap-sift", as
    run-images' does, but a rendered formation takes the rule's radius with every feature
    method (2 px with the evidence rule): the formation commands no longer claim it."""
    from pipeline.__main__ import build_parser
    from pipeline.stages import merge_radius_for, photo_merge_radius

    sub = build_parser([command])._subparsers._group_actions[0].choices[command]
    text = next(a.help for a in sub._actions if "--merge-radius" in a.option_strings)
    used = (photo_merge_radius if command == "run-images"
            else lambda f, r, m: merge_radius_for(r, m))("colmap-sift", "evidence", None)
    assert used == colmap_sift_radius
    assert ("0.5 px with colmap-sift" in text) == (colmap_sift_radius == 0.5)
    assert "2 px (the truth tolerance) with --resolution evidence" in text


def test_max_features_auto_help_states_the_floor_the_budget_keeps():
    """run-images' --help said 'with the other methods 2000 per 640x480 pixels, at most 8192':
    a 320x240 photograph read as 500 features, but it gets 2000 (the budget's floor)."""
    from pipeline.matching.features import photo_max_features

    p = argparse.ArgumentParser()
    add_feature_options(p, photos=True)
    text = next(a.help for a in p._actions if "--max-features" in a.option_strings)
    low, high = photo_max_features(320, 240), photo_max_features(4000, 3000)
    assert (low, high) == (2000, 8192)
    assert f"2000 per 640x480 pixels, from {low} to {high}" in text


@pytest.mark.parametrize("command, out", [("clean-db", "OUT.db"), ("clean-h5", "OUT.h5")])
def test_cleaning_commands_help_names_the_side_files_overwrite_replaces(command, out):
    """clean-db's --help said '--out OUT.db: the cleaned database to write' and '--overwrite:
    replace OUT.db / --report', but it also refuses (and with --overwrite replaces) the
    OUT.links.csv and OUT.rrd it writes beside OUT.db, as clean-h5's help says."""
    from pipeline.__main__ import build_parser

    sub = build_parser([command])._subparsers._group_actions[0].choices[command]
    helps = {a.option_strings[0]: a.help for a in sub._actions if a.option_strings}
    assert "OUT.links.csv and OUT.rrd are written beside it" in helps["--out"]
    assert f"replace {out}, its side files and --report" in helps["--overwrite"]
