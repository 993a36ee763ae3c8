"""``python -m pipeline run-formation``: the whole pipeline on a rendered formation."""

from __future__ import annotations

import argparse
import json
import math

from data_synth import check_formation
from data_synth.motion import DEFAULT_SPEED, MAX_SPEED
from pipeline import validate
from pipeline.commands.options import (
    add_feature_options,
    add_memory_option,
    add_merge_radius_option,
    add_online_options,
    add_resolution_option,
    add_scene_options,
    add_transport_option,
    check_online_options,
    feature_options,
    online_run_summary,
    parse_size,
    refuse_online_options,
)
from pipeline.errors import InputError
from pipeline.faults import (
    add_fault_arguments,
    check_faults_for_transport,
    faults_from_args,
    warn_rule_under_faults,
)
from pipeline.progress import counted
from pipeline.runs.formation import FormationConfig


def formation_choice(args) -> str:
    """``--formation`` (default d); refused beside ``--robots/--graph``, which render a
    parametric formation instead of one of a–d."""
    if args.robots is not None and args.formation is not None:
        raise InputError(f"--formation {args.formation} with --robots/--graph: those render a "
                         "parametric formation, not one of a-d; drop one of them")
    return "d" if args.formation is None else args.formation


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--formation", default=None,
                   help="formation a|b|c|d (comm graphs of increasing cycles; default d), or a "
                        "graph kind (line, ring, ring2, complete, geometric: the paper's 6 "
                        "robots on it); not "
                        "with --robots/--graph (a parametric formation)")
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
    add_resolution_option(p, faults=True)
    add_merge_radius_option(p, online="--steps")
    add_fault_arguments(p)
    add_transport_option(p)
    add_memory_option(p)
    g = p.add_argument_group("a formation in motion (online association)")
    g.add_argument("--steps", type=int, default=None,
                   help="drive the formation along the facade for N steps, one frame per robot "
                        "per step, and associate online (pipeline.runs.online); default: one "
                        "snapshot")
    add_online_options(g, "--steps")
    g.add_argument("--speed", type=float, default=None,
                   help=f"with --steps: metres the formation drives per step (default "
                        f"{DEFAULT_SPEED})")



def config_from_args(args) -> FormationConfig:
    from pipeline.budget import check_formation_memory

    if (args.robots is None) != (args.graph is None):
        raise InputError("--robots and --graph go together (a parametric formation needs both)")
    args.formation = formation_choice(args)
    method, max_features = feature_options(args)
    robots = None if args.robots is None else validate.robots(args.robots)
    size = parse_size(args.size)
    from pipeline.stages import check_merge_radius, merge_radius_for

    merge_radius_for(args.resolution, args.merge_radius)  # before the render, not after
    check_merge_radius(args.merge_radius, [size], f"--size {args.size}")
    # formations a-d: the paper's 6 robots
    check_formation_memory(robots if robots is not None else 6, size, args.max_memory_gb)
    check_formation(args.formation)  # before the render stage opens
    from pipeline.runs.transports import check_team_size

    check_team_size(args.transport, robots if robots is not None else 6, "robots")
    faults = faults_from_args(args)
    faults.check_robots(robots if robots is not None else 6)  # before the render, not after
    check_faults_for_transport(faults, args.transport)
    warn_rule_under_faults(faults, args.resolution)
    return FormationConfig(formation=args.formation, seed=validate.seed(args.seed, "--seed"),
                           size=size,
                           features=method, max_features=max_features,
                           robots=robots, graph=args.graph,
                           tol_px=validate.tolerance_px(args.tol_px),
                           fusion=not args.no_fusion, out=args.out, rerun=not args.no_rerun,
                           faults=faults,
                           resolution=args.resolution,
                           merge_radius=args.merge_radius,
                           max_memory_gb=args.max_memory_gb)


def online_config_from_args(args):
    """The :class:`pipeline.runs.online.OnlineConfig` of ``run-formation --steps N``."""
    from pipeline.budget import check_motion_memory
    from pipeline.runs.online import OnlineConfig
    from pipeline.stages import check_merge_radius, merge_radius_for

    if args.steps < 1:
        raise InputError(f"--steps {args.steps}: expected a number of steps >= 1")
    check_online_options(args)
    if args.speed is None:
        args.speed = DEFAULT_SPEED
    if not (math.isfinite(args.speed) and 0 <= args.speed <= MAX_SPEED):
        raise InputError(f"--speed {validate.shown(args.speed)}: expected a finite number of metres per step "
                         f"from 0 to {MAX_SPEED:g} (the scene is tens of metres long)")
    from pipeline.runs.transports import get_transport

    if not args.no_fusion and not hasattr(get_transport(args.transport).load(), "online_fusion"):
        raise InputError(f"--steps over --transport {args.transport}: this transport runs no "
                         "fusion of the changed tracks; add --no-fusion")
    if (args.robots is None) != (args.graph is None):
        raise InputError("--robots and --graph go together (a parametric formation needs both)")
    args.formation = formation_choice(args)
    method, max_features = feature_options(args)
    robots = None if args.robots is None else validate.robots(args.robots)
    # before faults_from_args, whose advice for a seed without drops (add --drop-prob) an
    # online run refuses
    fault_seed = validate.seed(args.fault_seed, "--fault-seed")
    if fault_seed != 0:
        raise InputError(f"--fault-seed {fault_seed}: an online run (--steps) draws the graph "
                         "of each step from --seed, the scene's seed; drop --fault-seed, or "
                         "change --seed")
    faults = faults_from_args(args)
    if faults is not None:
        given = ([f"--drop-prob {args.drop_prob}"] if faults.drop_prob else []) \
            + ([f"--delay-rounds {args.delay_rounds}"] if faults.delay_rounds else []) \
            + [f"--crash {c}" for c in args.crash]
        if given:
            raise InputError(f"{', '.join(given)}: an online run (--steps) models only "
                             "--switching-topology (the graph of each step); drop "
                             f"{'it' if len(given) == 1 else 'them'}")
    switching = bool(faults is not None and faults.switching_topology)
    if switching and args.window == 1:
        from pipeline.progress import log

        # data_synth.motion forces every edge up once every --window steps
        log.warning("warning: --switching-topology with --window 1: every communication link "
                    "is forced up at every step (each comes up at least once every --window "
                    "steps), so the graph does not switch; use --window 2 or more")
    check_formation(args.formation)
    size = parse_size(args.size)
    merge_radius = None if args.merge_radius is None else \
        merge_radius_for(args.resolution, args.merge_radius)
    check_merge_radius(merge_radius, [size], f"--size {args.size}")
    check_motion_memory(robots if robots is not None else 6, args.steps, size,
                        args.max_memory_gb)  # every frame is rendered before the first step
    from pipeline.runs.transports import check_online_team_size

    check_online_team_size(args.transport, robots if robots is not None else 6, args.window,
                           args.hold, args.steps)
    return OnlineConfig(formation=args.formation, seed=validate.seed(args.seed, "--seed"),
                        size=size, features=method,
                        max_features=max_features or 2000, robots=robots, graph=args.graph,
                        steps=args.steps, window=args.window, hold=args.hold,
                        speed=args.speed, switching=switching,
                        resolution=args.resolution,
                        tol_px=validate.tolerance_px(args.tol_px),
                        batch_every=args.batch_every, fusion=not args.no_fusion, out=args.out,
                        rerun=not args.no_rerun, transport=args.transport,
                        merge_radius=merge_radius)


def run(args) -> int:
    from pipeline.outcome import exit_status
    from pipeline.runfolder import claim_run_folder
    from pipeline.runs.formation import run_formation

    validate.not_empty(args.out, "--out")  # not the default run folder, which it replaced
    if args.steps is not None:
        return _run_online(args)
    refuse_online_options(args, "--steps N")
    if args.speed is not None:
        raise InputError("--speed applies to an online job only; add --steps N or drop it")
    config = config_from_args(args)
    with claim_run_folder(config.out_dir()):
        out = run_formation(config, transport=args.transport)
    written = "report.json, links.csv, sparse/" + ("" if args.no_rerun else ", recording.rrd")
    print(f"run written to {out}/ ({written})")
    return exit_status(json.loads((out / "report.json").read_text()))


def _run_online(args) -> int:
    from pipeline.evaluation.metrics import score_text
    from pipeline.runfolder import claim_run_folder
    from pipeline.runs.online import run_online

    config = online_config_from_args(args)
    with claim_run_folder(config.out_dir()):
        out = run_online(config)
    report = json.loads((out / "report.json").read_text())
    f = report["final"]
    return online_run_summary(
        report, out, f"{counted(len(report['steps']), 'step')}, {counted(f['links'], 'link')}, "
        "conflict-free after "
        f"every step: {report['conflict_free_every_step']}; pairwise F1 online "
        f"{score_text(f['online'], 'f1')}"
        + (f", batch {score_text(f['batch'], 'f1')}" if "batch" in f else ""),
        args.no_rerun)
