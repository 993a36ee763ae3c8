"""``python -m pipeline run-formation``: the whole pipeline on a rendered formation."""

from __future__ import annotations

import argparse
import json

from pipeline import validate
from pipeline.commands.options import (
    add_feature_options,
    add_memory_option,
    add_merge_radius_option,
    add_resolution_option,
    add_scene_options,
    add_transport_option,
    feature_options,
    parse_size,
)
from pipeline.errors import InputError
from pipeline.faults import add_fault_arguments, faults_from_args
from pipeline.runs.formation import FormationConfig


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--formation", default="d",
                   help="formation a|b|c|d (comm graphs of increasing cycles; default d)")
    add_feature_options(p)
    add_scene_options(p)
    p.add_argument("--robots", default=None,
                   help=f"parametric formation: number of robots, 2 to {validate.MAX_ROBOTS} "
                        "(use with --graph)")
    p.add_argument("--graph", default=None,
                   help="parametric formation: line|ring|ring2|complete|geometric")
    p.add_argument("--tol-px", type=float, default=2.0,
                   help="ground-truth tolerance of a good link in pixels (default 2)")
    p.add_argument("--no-fusion", action="store_true", help="skip the fusion stage")
    p.add_argument("--no-rerun", action="store_true", help="do not write recording.rrd")
    p.add_argument("--out", default=None, help="run folder (default runs/formation-<name>)")
    add_resolution_option(p)
    add_merge_radius_option(p)
    add_fault_arguments(p)
    add_transport_option(p)
    add_memory_option(p)


def config_from_args(args) -> FormationConfig:
    from pipeline.budget import check_formation_memory

    if (args.robots is None) != (args.graph is None):
        raise InputError("--robots and --graph go together (a parametric formation needs both)")
    method, max_features = feature_options(args)
    robots = None if args.robots is None else validate.robots(args.robots)
    size = parse_size(args.size)
    # formations a-d: the paper's 6 robots
    check_formation_memory(robots if robots is not None else 6, size, args.max_memory_gb)
    return FormationConfig(formation=args.formation, seed=validate.seed(args.seed, "--seed"),
                           size=size,
                           features=method, max_features=max_features,
                           robots=robots, graph=args.graph,
                           tol_px=validate.tolerance_px(args.tol_px),
                           fusion=not args.no_fusion, out=args.out, rerun=not args.no_rerun,
                           faults=faults_from_args(args),
                           resolution=args.resolution,
                           merge_radius=args.merge_radius)


def run(args) -> int:
    from pipeline.outcome import exit_status
    from pipeline.runfolder import claim_run_folder
    from pipeline.runs.formation import run_formation

    config = config_from_args(args)
    with claim_run_folder(config.out_dir()):
        out = run_formation(config, transport=args.transport)
    written = "report.json, links.csv, sparse/" + ("" if args.no_rerun else ", recording.rrd")
    print(f"run written to {out}/ ({written})")
    return exit_status(json.loads((out / "report.json").read_text()))
