"""The ``run-images DIR --sequence`` job: a folder of per-robot frame sequences, associated
online step by step.

``DIR`` holds one sub-folder per robot with its frames in name order
(:mod:`pipeline.inputs.sequence`); step ``k`` is every robot's ``k``-th frame. The robots'
communication graph is ``--graph`` over the robots (a kind, or a file of sub-folder names or
indices), the same at every step. Each step runs what ``run-formation --steps N`` runs
(:func:`pipeline.runs.online.associate_online`): the new frames' features (SIFT as
``run-images`` extracts photographs: RootSIFT, COLMAP's contrast threshold), matching against
the robot's ``W - 1`` previous frames and its neighbours' last ``W`` frames, the online stage
(:class:`pipeline.consistency.engines.online.OnlineAssociation`), the conflict check after
the step; the batch run from scratch at the last step (and every ``batch_every`` steps).
Photographs come without poses, so there is no fusion and the evidence rule judges links on
their keypoints without its geometric test; there is no ground truth, so the report gives no
scores, only the step list and how the online and batch associations compare (links kept,
links on which they agree).

Outputs (run folder, written atomically): ``report.json`` (``steps``: one entry per step
with ``links_new``, ``conflictive_sets_after``, ``wall_s``, ``rounds``, ``bytes`` and the rest
of the online record), ``links.csv`` (cameras are frames; ``round`` is the step that cut the
link; ``truth`` empty), ``images.csv`` (frame -> robot, step, ``<sub-folder>/<file>``),
``link_steps.csv`` and ``recording.rrd`` on a ``step`` timeline (robots on a step x robot grid:
photographs have no positions).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pipeline.consistency.rules import DEFAULT_RESOLUTION
from pipeline.progress import StageTimer, counted

__all__ = ["SequenceConfig", "run_images_sequence"]


@dataclass
class SequenceConfig:
    """Options of ``run-images DIR --sequence``."""

    directory: str
    graph: str = "complete"
    window: int = 3
    hold: int | None = None  # None: the stage's default (window - 1)
    intrinsics: str = "auto"
    max_size: int | None = 1600
    features: str = "sift"
    max_features: int | None = None
    matcher: str = "opencv"
    #: SIFT as ``run-images`` extracts it from photographs
    #: (:class:`pipeline.runs.images.ImagesConfig`): COLMAP's contrast threshold, RootSIFT
    #: descriptors (unit length, as COLMAP's matcher takes them), the budget counting
    #: distinct locations
    contrast_threshold: float | None = 0.02
    rootsift: bool = True
    budget_after_merge: bool = True
    resolution: str = DEFAULT_RESOLUTION
    batch_every: int = 0
    out: str | None = None
    rerun: bool = True
    #: where the robots run the rule's stage of each step (:mod:`pipeline.runs.transports`)
    transport: str = "sim"
    #: keypoints of one frame closer than this are one feature (None: as ``run-images``,
    #: :func:`pipeline.stages.photo_merge_radius`)
    merge_radius: float | None = None

    def out_dir(self) -> Path:
        if self.out:
            return Path(self.out)
        graph = Path(self.graph).stem if Path(self.graph).is_file() else \
            self.graph.replace(":", "")
        return Path("runs") / f"sequence-{Path(os.path.realpath(self.directory)).name}-{graph}"


def run_images_sequence(config: SequenceConfig, timer: StageTimer | None = None) -> Path:
    """Run the job (module docstring), write its run folder and return its path."""
    from pipeline.commgraph import comm_graph, split_warning
    from pipeline.inputs.sequence import load_sequence
    from pipeline.matching.pairs import check_matcher
    from pipeline.runs.online import associate_online, batch_steps_of, online_tables
    from pipeline.stages import check_merge_radius, photo_merge_radius

    timer = timer or StageTimer()
    check_matcher(config.matcher, config.features)  # before any work
    with timer.stage("load", config.directory):
        # a graph file is read on the robots' names before any frame is decoded
        seq = load_sequence(config.directory, config.max_size, config.intrinsics,
                            check_robots=lambda robots: comm_graph(config.graph, robots,
                                                                   what="robot"))
    check_merge_radius(config.merge_radius, [v.size for v in seq.views], "the smallest frame "
                       "as loaded (after --max-size)")  # before the features
    if seq.ignored:
        timer.warn(f"{len(seq.ignored)} image(s) directly in {config.directory} belong to no "
                   f"robot and are not used ({', '.join(seq.ignored[:3])}"
                   f"{', ...' if len(seq.ignored) > 3 else ''}): a robot's frames go in its "
                   "sub-folder")
    if seq.empty:
        timer.warn(f"{len(seq.empty)} sub-folder(s) of {config.directory} hold no image and are "
                   f"no robot ({', '.join(seq.empty[:3])}{', ...' if len(seq.empty) > 3 else ''})")
    from pipeline.inputs.photos import identical_pixels

    same = identical_pixels(seq.views)
    if same:
        timer.warn(f"{len(same)} group(s) of frames have identical pixels "
                   f"({'; '.join(' = '.join(g) for g in same[:3])}{'; ...' if len(same) > 3 else ''}"
                   "): the same photograph twice matches itself and adds nothing (a robot's "
                   "folder copied or linked as another's?)")
    if seq.broken:
        timer.warn(f"{len(seq.broken)} symbolic link(s) in {config.directory} lead nowhere and "
                   f"are no robot ({', '.join(seq.broken[:3])}"
                   f"{', ...' if len(seq.broken) > 3 else ''}): a robot's frames on a drive not "
                   "mounted? fix or remove the links")
    from pipeline.runs.transports import check_online_team_size

    check_online_team_size(config.transport, seq.n_robots, config.window, config.hold,
                           seq.steps)
    edges = comm_graph(config.graph, seq.robots, what="robot")
    timer.note(f"{seq.n_robots} robots, {counted(seq.steps, 'step')}, comm edges {edges.tolist()}")
    message = split_warning(seq.n_robots, edges, "robots", "their frames cannot be associated "
                            "across the groups")
    if message:
        timer.warn(message)
    radius = photo_merge_radius(config.features, config.resolution, config.merge_radius)
    run = associate_online(seq.views, seq.n_robots, [edges] * seq.steps, config.window,
                           config.resolution, timer, features=config.features,
                           max_features=config.max_features, fusion=False,
                           feature_options={"merge_radius": radius,
                                            "contrast_threshold": config.contrast_threshold,
                                            "rootsift": config.rootsift,
                                            "budget_after_merge": config.budget_after_merge},
                           batch_steps=batch_steps_of(seq.steps, config.batch_every)
                           | {seq.steps - 1},
                           match_options=dict(threshold_px=None, matcher=config.matcher),
                           transport=config.transport,
                           hold=config.hold)
    oa = run.online
    kept = oa.links.kept
    final = {"links": int(len(kept)), "online": {"kept": int(kept.sum()),
                                                 "conflictive_sets":
                                                 int(run.steps[-1]["conflictive_sets_after"])}}
    if run.batch is not None:
        kb = ~run.batch.deleted
        final["batch"] = {"kept": int(kb.sum()),
                          "conflictive_sets": int(run.steps[-1]["batch"]
                                                  ["conflictive_sets_after"]),
                          "links_decided_alike": int((kb == kept).sum())}
    from pipeline.evaluation.report import versions
    from pipeline.runs.online import jsonable_step

    report = {
        "title": f"{seq.n_robots} robots' frame sequences from {config.directory} "
                 f"({counted(seq.steps, 'step')})",
        "n_robots": int(seq.n_robots), "robots": seq.robots,
        "n_images": int(oa.n_images), "comm_edges": edges.tolist(),
        "features_per_camera": [int(len(f)) for f in run.features],
        "window": int(config.window), "hold": int(oa.hold), "resolution": oa.resolution,
        "steps": [jsonable_step(r) for r in run.steps], "final": final,
        "conflict_free_every_step": bool(all(r["conflictive_sets_after"] == 0
                                             for r in run.steps)),
        "fusion": {"enabled": False, "scope": "photographs have no poses"},
        "versions": versions(),
        "config": {**asdict(config), "out": str(config.out_dir())},
    }
    from pipeline.outcome import flag_online

    flag_online(report, "frames too small, too few features, or no overlap between the "
                        "robots' frames", [v.name for v in seq.views])
    n = seq.n_robots
    grid = np.array([[float(k), float(i), 0.0] for k in range(seq.steps) for i in range(n)])
    online_tables(config.out_dir(), run, report, timer, [v.name for v in seq.views],
                  rerun=config.rerun, centres=grid)
    return config.out_dir()
