"""The ``sim`` transport: every robot is an object of this process, on the simulated network.

The jobs chain the stages of :mod:`pipeline.stages` (faults, when asked for, are properties
of the simulated network, :mod:`pipeline.faults`). The job functions are those of the
registry (:mod:`pipeline.runs.transports`).
"""

from __future__ import annotations

import contextlib

import numpy as np

from pipeline import stages
from pipeline.consistency.engines.online import simulated_stage
from pipeline.runs.transports.results import FormationRobots, ImagesRobots

__all__ = ["formation", "images", "online_robots", "online_match", "online_stage",
           "resolve"]  # and online_fusion (__getattr__)


def formation(config, timer) -> FormationRobots:
    """Render the formation, then features, matching, consistency and fusion in this process."""
    import data_synth
    from data_synth import formation_name

    with timer.stage("render", f"{formation_name(config.formation, config.robots, config.graph)}"
                     f", seed {config.seed}, {config.size[0]}x{config.size[1]}"):
        rendered = data_synth.render(config.formation, seed=config.seed, size=config.size,
                                     n_robots=config.robots, graph=config.graph)
        views, comm_edges = rendered.views, np.asarray(rendered.comm_edges)
    feats, matches, links = stages.extract_and_match(
        views, comm_edges, config.features, config.max_features, timer,
        merge_radius=stages.merge_radius_for(config.resolution, config.merge_radius))
    cleaning = stages.clean_association(views, feats, comm_edges, links, fusion=config.fusion,
                                 faults=config.faults, timer=timer,
                                 resolution=config.resolution, matches=matches,
                                 max_memory_gb=config.max_memory_gb)
    return FormationRobots(rendered, feats, matches, cleaning)


def images(config, views, comm_edges, timer, graph_from_features) -> ImagesRobots:
    """Features and matching of the photographs; the runner runs the consistency stage."""
    feats, matches, links = stages.extract_and_match(
        views, graph_from_features if comm_edges is None else comm_edges, config.features,
        config.max_features, timer, contrast_threshold=config.contrast_threshold,
        merge_radius=stages.merge_radius_for(config.resolution, config.merge_radius),
        rootsift=config.rootsift, threshold_px=config.threshold_px,
        budget_after_merge=config.budget_after_merge, matcher=config.matcher)
    return ImagesRobots(feats, matches, links)


@contextlib.contextmanager
def online_robots():
    """What the robots of an online run keep from step to step (:func:`online_match`): each
    frame's features while the frame is in a matching window, in this process."""
    yield {}


def online_match(views, t: int, n: int, window: int, edges_up, store: dict, *, features: str,
                 max_features, merge_radius: float, feature_options: dict,
                 match_options: dict):
    """An online step's matching in this process: the new frames' features (robot ``i``'s
    frame ``t · n + i``), kept in ``store`` while in the window, and the pairs of
    :func:`pipeline.matching.pairs.step_pairs` matched as :func:`pipeline.matching.pairs.
    match_edges` matches them. Returns ``(features, links, stats)`` as the registry says."""
    from pipeline.matching.features import extract_all
    from pipeline.matching.pairs import match_edges, step_pairs
    from pipeline.types import Links

    ids = [t * n + i for i in range(n)]
    feats = extract_all([views[g] for g in ids], features, max_features, merge_radius,
                        **feature_options)
    store.update(zip(ids, feats, strict=True))
    for g in [g for g in store if g // n <= t - window]:  # left every matching window
        del store[g]
    frames = np.arange((t + 1) * n)
    pairs = step_pairs(frames % n, frames // n, t, window, edges_up)
    local = np.unique(pairs)
    # COLMAP's verification on several threads draws its RANSAC samples otherwise from run to
    # run (a pair of 121 inliers on one run had none on the next); on one, every pair gets
    # what a robot matching it alone gets (pipeline.team.online_match)
    one = {"workers": 1} if match_options.get("matcher") == "colmap" else {}
    lk = Links.from_matches(match_edges([store[g] for g in local], [views[g] for g in local],
                                        np.searchsorted(local, pairs), **match_options, **one))
    links = Links(local[lk.cam_i], lk.feat_i, local[lk.cam_j], lk.feat_j, lk.quality)
    return feats, links, {"pairs": int(len(pairs)),
                          "descriptor_bytes": [int(f.descriptors.nbytes) for f in feats]}


#: the rule's stage of one online step on its sub-problem (frames as cameras, cameras
#: sharing a link as neighbours) on the simulated network: the online stage's own default
online_stage = simulated_stage


def __getattr__(name: str):
    """``online_fusion``: the fusion of one online step's changed tracks (frames as robots) in
    this process, robust distributed fusion itself (Montijano et al., dynamic voting:
    :func:`pipeline.fusion.landmarks.fuse_tracks`), imported when first asked for, so that a
    run without fusion loads none of it."""
    if name == "online_fusion":
        from pipeline.fusion.landmarks import fuse_tracks

        return fuse_tracks
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def resolve(features_per_camera, comm_edges, links, faults, resolution, ids, evidence=None):
    """The consistency stage on the simulated network, its faults in the layout of ``ids``
    (``evidence``: :func:`pipeline.stages.consistency_stage`'s)."""
    from pipeline.inputs.compact import faults_in_layout

    # the stage shows its own round counter on a long run (pipeline.progress.rounds_bar)
    return stages.consistency_stage(features_per_camera, comm_edges, links,
                             None if faults is None else faults_in_layout(faults, ids),
                             resolution=resolution, evidence=evidence)
