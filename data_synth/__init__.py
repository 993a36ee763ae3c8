"""Synthetic robot formations with ground truth (Aragüés et al., Sec. V-B, Fig. 4).

``render(formation, seed)`` places 6 robots in formation in front of a textured scene with
repeated structure, renders each robot's camera (image, ``K``, ``cam_from_world``, depth) and
returns the communication graph of formation ``a``–``d``, the four graphs of the paper's Fig. 4
as :mod:`data_synth.formations` defines them (the figure is not in the paper's text; that module
gives the explicit edge lists); see :mod:`data_synth.ground_truth` for
good / spurious / missing links.

Example
-------
>>> import data_synth
>>> f = data_synth.render("d", seed=0)
>>> len(f.views), f.comm_edges.shape
(6, (15, 2))
"""

from __future__ import annotations

import numbers

import numpy as np

from data_synth import cache as render_cache
from data_synth.formations import (
    FIG4_EDGES,
    FORMATIONS,
    GRAPH_KINDS,
    Formation,
    graph_edges,
    robot_poses,
)
from data_synth.ground_truth import good_links, points_from_keypoints, true_pairs
from data_synth.renderer import intrinsics, render_view
from data_synth.scene import build_scene
from pipeline.errors import InputError
from pipeline.types import View
from pipeline.validate import MAX_RENDER_PIXELS, MAX_RENDER_SIDE, MAX_ROBOTS

__all__ = [
    "formation_name",
    "formation_used",
    "render",
    "render_robot",
    "formation_edges",
    "Formation",
    "FORMATIONS",
    "FIG4_EDGES",
    "GRAPH_KINDS",
    "points_from_keypoints",
    "good_links",
    "true_pairs",
    "MIN_SIZE",
]

MIN_SIZE = (64, 48)
"""Smallest image size ``(W, H)`` accepted by :func:`render`."""


def check_int(value, name: str, minimum: int) -> int:
    """``value`` as an int, or InputError naming ``name`` if it is not an integer >= minimum."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def render(formation: str = "d", seed: int = 0, size: tuple[int, int] = (640, 480),
           n_robots: int | None = None, graph: str | None = None,
           cache: bool = True) -> Formation:
    """Render a formation: one view per robot plus the communication graph.

    Parameters
    ----------
    formation : str
        ``a``, ``b``, ``c`` or ``d`` — the paper's four communication graphs from few cycles to
        complete (:data:`FIG4_EDGES`); or a graph kind (``line``, ``ring``, ``ring2``,
        ``complete``, ``geometric``) as a shorthand for ``graph=``.
    seed : int
        Drives the scene textures, the formation jitter and the sensor noise. The camera poses
        and images do not depend on the graph: formations ``a``–``d`` with one seed share images.
    size : (W, H)
        Image size in whole pixels, at least :data:`MIN_SIZE`.
    n_robots : int, optional
        Number of robots (default 6); for ``n != 6`` formations ``a``–``d`` follow their rules
        (ring, ring + triangles, ring2, complete).
    graph : str, optional
        Overrides the communication graph kind.
    cache : bool
        Read and write the views through the on-disk render cache (:mod:`data_synth.cache`;
        ``FORMATION_MATCH_CACHE=off`` turns it off for every call). The cached views are the
        rendered ones bit for bit.

    Returns
    -------
    Formation

    Raises
    ------
    InputError
        Unknown formation or graph kind, ``n_robots < 2``, image smaller than ``MIN_SIZE``
        or larger than the command line allows (``pipeline.validate.MAX_RENDER_SIDE`` a side,
        ``MAX_RENDER_PIXELS`` in all).
    """
    seed = check_int(seed, "seed", 0)  # a Python int: numpy's int64 wraps in seed * 1000
    name, kind, n, (W, H), centres, poses, edges, K = formation_setup(formation, seed, size, n_robots,
                                                             graph)
    # the views depend on seed, size and robots only (not on the graph): one cache entry each
    pixels = render_cache.load_views(seed, (W, H), n) if cache else None
    if pixels is None:
        scene = build_scene(seed)
        rendered = [render_view(scene, K, R, t, (W, H), rng=np.random.default_rng([seed, 3, i]))
                    for i, (R, t) in enumerate(poses)]
        pixels = {"image": [im for im, _ in rendered], "depth": [d for _, d in rendered]}
        if cache:
            render_cache.save_views(seed, (W, H), {k: np.stack(v) for k, v in pixels.items()})
    views = [View(name=f"cam{i:02d}", image=pixels["image"][i], K=K.copy(), R=R, t=t,
                  depth=pixels["depth"][i], intrinsics_known=True)
             for i, (R, t) in enumerate(poses)]
    return Formation(name=name, views=views, comm_edges=edges, graph=kind, seed=seed,
                     centres=centres)


def formation_edges(formation: str = "d", seed: int = 0, n_robots: int | None = None,
                    graph: str | None = None) -> np.ndarray:
    """The communication graph ``(E, 2)`` of a formation, without rendering anything."""
    return formation_setup(formation, seed, MIN_SIZE, n_robots, graph)[6]


def render_robot(robot: int, formation: str = "d", seed: int = 0,
                 size: tuple[int, int] = (640, 480), n_robots: int | None = None,
                 graph: str | None = None) -> tuple[View, np.ndarray]:
    """Render only robot ``robot``'s camera of a formation (what a robot process needs).

    The view is identical to ``render(...).views[robot]`` (same scene, pose and noise seed).
    It is read from the machine's render cache when the formation's views are there
    (:mod:`data_synth.cache`); otherwise only this camera is rendered (the cache is not
    written: it holds whole formations).

    Returns
    -------
    view : View
    comm_edges : ndarray, (E, 2) int64 — the formation's communication graph

    Raises
    ------
    InputError
        As :func:`render`, or ``robot`` outside ``0..n-1``.
    """
    seed = check_int(seed, "seed", 0)  # a Python int: numpy's int64 wraps in seed * 1000
    _, _, n, (W, H), _, poses, edges, K = formation_setup(formation, seed, size, n_robots, graph)
    if isinstance(robot, bool) or not isinstance(robot, numbers.Integral) or not 0 <= robot < n:
        raise InputError(f"robot {robot!r} is not in the formation; robots are 0..{n - 1}")
    i = int(robot)
    R, t = poses[i]
    pixels = render_cache.load_view(seed, (W, H), n, i)
    if pixels is not None:
        image, depth = pixels["image"], pixels["depth"]
    else:
        image, depth = render_view(build_scene(seed), K, R, t, (W, H),
                                   rng=np.random.default_rng([seed, 3, i]))
    return View(name=f"cam{i:02d}", image=image, K=K.copy(), R=R, t=t, depth=depth,
                intrinsics_known=True), edges


def formation_name(formation: str, robots: int | None, graph: str | None,
                   n_edges: int | None = None) -> str:
    """What a report calls the formation: ``formation d``, or a parametric one by its robots
    and graph (``3 robots on a line graph``; its ``formation`` value is not one of a–d).

    Robots without a graph kind (a team file without ``data.graph``, whose robots talk over
    its own ``comm_edges``) are named by those: ``3 robots on 2 comm edges`` (``n_edges``),
    else by the formation whose rule drew their graph (``3 robots, formation d``).
    """
    if robots is None:
        return f"formation {formation}"
    if graph is not None:
        return f"{robots} robots on a {graph} graph"
    if n_edges is not None:
        return f"{robots} robots on {n_edges} comm edge{'' if n_edges == 1 else 's'}"
    return f"{robots} robots, formation {formation}"


def formation_used(formation: str, graph: str | None) -> str | None:
    """The formation a render used: ``None`` beside a graph kind, which draws the graph in its
    place (``run-formation --robots N --graph G``, a parametric formation)."""
    return formation if graph is None else None


def check_formation(formation) -> None:
    """InputError unless ``formation`` names one: a–d (our four graphs for the paper's Fig. 4,
    :mod:`data_synth.formations`) or a graph kind."""
    if not isinstance(formation, str) or (formation not in FORMATIONS and formation not in GRAPH_KINDS):
        raise InputError(f"unknown formation {formation!r}; choose one of "
                         f"{', '.join(FORMATIONS)} (the paper's Fig. 4) or a graph kind "
                         f"({', '.join(GRAPH_KINDS)})")


def formation_setup(formation, seed, size, n_robots, graph):
    """Checked parameters, poses, comm edges and intrinsics shared by all robots."""
    check_formation(formation)
    if graph is not None and graph not in GRAPH_KINDS:
        raise InputError(f"unknown graph kind {graph!r}; choose one of {', '.join(GRAPH_KINDS)}")
    seed = check_int(seed, "seed", 0)
    n = 6 if n_robots is None else check_int(n_robots, "n_robots", 2)
    if n > MAX_ROBOTS:  # the poses and graph alone grow with n (10**9 exhausted the memory)
        raise InputError(f"n_robots {n}: at most {MAX_ROBOTS} robots (line abreast 0.8 m apart, "
                         "beyond a few hundred most see nothing of the facade)")
    try:
        W, H = size
    except (TypeError, ValueError):
        raise InputError(f"size must be (width, height) in pixels, got {size!r}") from None
    if any(isinstance(v, bool) or not isinstance(v, numbers.Integral) for v in (W, H)):
        raise InputError(f"size must be (width, height) in whole pixels, got {size!r}")
    W, H = int(W), int(H)
    if W < MIN_SIZE[0] or H < MIN_SIZE[1]:
        raise InputError(f"image size {W}x{H} is too small; use at least {MIN_SIZE[0]}x{MIN_SIZE[1]}")
    if W > MAX_RENDER_SIDE or H > MAX_RENDER_SIDE or W * H > MAX_RENDER_PIXELS:
        raise InputError(f"image size {W}x{H} is too large; each side at most {MAX_RENDER_SIDE} "
                         f"and at most {MAX_RENDER_PIXELS} pixels in all (e.g. 4096x4096)")

    if graph is None:
        kind = FORMATIONS.get(formation, formation)
    else:
        kind = graph
    name = formation if (formation in FORMATIONS and graph is None and n == 6) else f"{kind}-n{n}"

    centres, poses = robot_poses(n, seed)
    if name in FIG4_EDGES:
        edges = np.array(FIG4_EDGES[name], np.int64)
        edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
    else:
        edges = graph_edges(kind, n, centres, seed)
    K = intrinsics((W, H))
    return name, kind, n, (W, H), centres, poses, edges, K
