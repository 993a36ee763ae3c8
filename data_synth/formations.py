"""Robot formations and their communication graphs (Aragüés et al., Sec. V-B and Fig. 4).

The paper's image experiment has 6 robots moving in formation, each taking one image, and
compares four communication graphs "(a) … (d)" whose number of cycles grows; local matching is
done only along communication edges. Fig. 4 itself is not in the text we have, so the four
graphs are defined here explicitly, from few cycles to the complete graph.

The robots drive line abreast on flat ground — robots 0..5 left to right, 0.8 m apart, all
cameras at the same mount height, each gazing at a slightly different point of the facade::

        facade (+y)
      0 ─ 1 ─ 2 ─ 3 ─ 4 ─ 5      (ring edge (0, 5) closes the loop)

Because every baseline is (nearly) parallel to the facade's window rows, to the rows of floor
tiles and to the row of crates, a copy of a structure along its row lies on the epipolar line of
the original: such wrong matches pass the epipolar RANSAC, as the paper reports for its images.

Communication graphs for 6 robots (``FIG4_EDGES``; cycle rank = E - n + 1):

====  =========================================================  ===  ==========
name  edges                                                      E    cycle rank
====  =========================================================  ===  ==========
(a)   ring: (0,1) (1,2) (2,3) (3,4) (4,5) (0,5)                  6    1
(b)   ring + triangles: (a) + (0,2) (3,5)                        8    3
(c)   ring + 2-hop chords: (a) + (0,2) (1,3) (2,4) (3,5) (0,4)   12   7
      (1,5)
(d)   complete: all 15 pairs                                     15   10
====  =========================================================  ===  ==========

For ``n != 6`` robots the same rules apply (``ring``, ``ring+triangles``, ``ring2``,
``complete``); parametric kinds ``line``, ``ring``, ``ring2``, ``complete`` and ``geometric``
(on the robots' positions). The rules live in :mod:`pipeline.commgraph`
(:func:`~pipeline.commgraph.graph_edges`), shared with the image path.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from data_synth.scene import FACADE_Y, Scene, build_scene
from pipeline.commgraph import GRAPH_KINDS, graph_edges

__all__ = [
    "Formation",
    "FIG4_EDGES",
    "FORMATIONS",
    "GRAPH_KINDS",
    "graph_edges",
    "robot_poses",
    "look_at",
]

FORMATIONS = {"a": "ring", "b": "ring+triangles", "c": "ring2", "d": "complete"}
"""Formation name -> graph rule (see the module docstring)."""

FIG4_EDGES = {
    "a": [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 5)],
    "b": [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 5), (0, 2), (3, 5)],
    "c": [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (0, 5),
          (0, 2), (1, 3), (2, 4), (3, 5), (0, 4), (1, 5)],
    "d": [(i, j) for i in range(6) for j in range(i + 1, 6)],
}
"""The four communication graphs of the 6-robot experiment, edges ``(i, j)`` with ``i < j``."""


@dataclass
class Formation:
    """A rendered formation: one view per robot and the communication graph.

    Attributes
    ----------
    name : str
        ``a``–``d`` for the paper's formations, else ``<graph>-n<robots>``.
    views : list[pipeline.types.View]
        Image, ``K``, ``cam_from_world`` ``(R, t)``, depth, ``intrinsics_known=True``.
    comm_edges : ndarray, (E, 2) int64
        Undirected communication edges, ``i < j``, sorted.
    graph : str
        Graph rule that produced ``comm_edges``.
    seed : int
    scene : data_synth.scene.Scene
        The rendered scene (faces and named landmarks), built from ``seed`` when first asked
        for (views read from the render cache need no scene).
    centres : ndarray, (n, 3)
        Camera centres in the world frame.

    Notes
    -----
    A formation is not modified after rendering: ground truth computed from its views (the
    true pairs of a camera pair, :func:`data_synth.ground_truth.true_pairs`, and the world
    points of each camera's keypoints they come from) is remembered with it.
    """

    name: str
    views: list
    comm_edges: np.ndarray
    graph: str
    seed: int
    centres: np.ndarray = field(repr=False)
    _truth_cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _camera_cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def scene(self) -> Scene:
        return build_scene(self.seed)

    @property
    def n_robots(self) -> int:
        return len(self.views)

    def neighbours(self, i: int) -> np.ndarray:
        """Communication neighbours of robot ``i``, sorted ``(d_i,)``."""
        e = self.comm_edges
        return np.sort(np.concatenate([e[e[:, 0] == i, 1], e[e[:, 1] == i, 0]]))


def look_at(centre, target, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """``cam_from_world`` ``(R, t)`` of a camera at ``centre`` looking at ``target``.

    Camera axes follow OpenCV: ``x`` right, ``y`` down, ``z`` forward.
    """
    c = np.asarray(centre, np.float64)
    z = np.asarray(target, np.float64) - c
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, np.float64))  # right
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ c


def robot_poses(n: int, seed: int, spacing: float = 0.8) -> tuple[np.ndarray, list]:
    """Camera centres and ``(R, t)`` of ``n`` robots driving line abreast towards the facade.

    Robot ``i`` stands at ``x = spacing * (i - (n - 1) / 2)``, ``y = 0``, camera height 1.5 m,
    with a small seeded jitter (±10 cm along the line, ±2 cm across it, ±1 cm in height: flat
    ground) and a seeded gaze target on the facade. The poses do not depend on the
    communication graph.

    Returns
    -------
    centres : (n, 3)
    poses : list of (R (3, 3), t (3,))
    """
    rng = np.random.default_rng([seed, 2])
    centres = np.zeros((n, 3))
    centres[:, 0] = spacing * (np.arange(n) - (n - 1) / 2) + rng.uniform(-0.1, 0.1, n)
    centres[:, 1] = rng.uniform(-0.02, 0.02, n)
    centres[:, 2] = 1.5 + rng.uniform(-0.01, 0.01, n)
    poses = []
    for i in range(n):
        target = np.array([0.3 * centres[i, 0] + rng.uniform(-0.4, 0.4), FACADE_Y,
                           1.9 + rng.uniform(-0.3, 0.3)])
        poses.append(look_at(centres[i], target))
    return centres, poses
