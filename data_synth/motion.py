"""A formation moving along a path: one frame per robot per step, with exact ground truth.

The robots keep their formation (:func:`data_synth.formations.robot_poses`: line abreast,
each gazing at its own point of the facade) and the whole formation drives along the facade
(``+x``) by ``speed`` metres per step, without turning: at step ``k`` robot ``i`` stands at
``centre_i + (speed * (k - (steps - 1) / 2), 0, 0)`` with its first orientation, so the path
is centred on the scene and a landmark leaves a camera's view after about ``view width /
speed`` steps. Every frame is rendered from the same scene as :func:`data_synth.render`
(same seed, same sensor-noise law: frame ``(i, k)`` draws its noise from
``[seed, 3, i, k]``).

The communication graph is the formation's (``formation``/``graph`` as in
:func:`data_synth.render`). With ``switching=True`` the graph of each step is drawn as the
simulated network's switching topology draws it per round
(:func:`pipeline.transport.simulated.recurrent_topology`: every edge up with probability
``p_up``, each edge up at least once every ``window`` steps): at step ``k`` only the robots of
an up edge exchange their frames.

Ground truth: :attr:`Sequence.flat` is a :class:`~data_synth.formations.Formation` whose
views are all the frames in arrival order (frame of robot ``i`` at step ``k`` is view
``k * n + i``); :func:`data_synth.ground_truth.true_pairs` and the evaluation work on it
unchanged, camera ``g`` being that frame.

Example
-------
>>> from data_synth.motion import render_motion
>>> s = render_motion("ring", seed=0, steps=2, size=(64, 48), n_robots=3)
>>> len(s.flat.views), s.step_edges[0].tolist()
(6, [[0, 1], [0, 2], [1, 2]])
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from data_synth import check_int, formation_setup
from data_synth.formations import Formation
from data_synth.renderer import render_view
from data_synth.scene import build_scene
from pipeline.budget import BYTES_PER_FRAME_PIXEL
from pipeline.errors import InputError
from pipeline.types import View

__all__ = ["Sequence", "render_motion", "DEFAULT_SPEED", "MAX_SPEED"]

DEFAULT_SPEED = 0.15
"""Metres the formation drives along the facade per step (default of :func:`render_motion`)."""
#: the fastest formation rendered (metres per step): the scene is tens of metres long, and the
#: projections of cameras near 1e308 m overflow
MAX_SPEED = 1e6


@dataclass
class Sequence:
    """A moving formation: every robot's frame at every step and who talks at each step.

    Attributes
    ----------
    name : str — the formation's name (as :attr:`Formation.name`)
    n_robots, steps : int
    comm_edges : ndarray, (E, 2) int64 — the formation's communication graph
    step_edges : list of (E_k, 2) int64 — the edges up at step ``k`` (all of ``comm_edges``
        without ``switching``)
    flat : Formation — all frames as one formation, view ``k * n_robots + i`` = robot ``i``
        at step ``k`` (the frame's name is ``r{i:02d}k{k:03d}``)
    speed : float — metres per step
    """

    name: str
    n_robots: int
    steps: int
    comm_edges: np.ndarray
    step_edges: list
    flat: Formation
    speed: float

    def frame(self, robot: int, step: int) -> View:
        """The view of ``robot`` at ``step``."""
        return self.flat.views[self.image(robot, step)]

    def image(self, robot: int, step: int) -> int:
        """Index of the frame of ``robot`` at ``step`` in :attr:`flat`."""
        return int(step) * self.n_robots + int(robot)


def _is_real(value) -> bool:
    """``value`` is a real number (a bool is not)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _physical_memory() -> int:
    """This machine's memory in bytes (a frame count beyond it can never be rendered)."""
    import os

    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def render_motion(formation: str = "d", seed: int = 0, steps: int = 10,
                  size: tuple[int, int] = (320, 240), n_robots: int | None = None,
                  graph: str | None = None, speed: float = DEFAULT_SPEED,
                  switching: bool = False, p_up: float = 0.5, window: int = 3) -> Sequence:
    """Render a formation driving along the facade for ``steps`` steps.

    Parameters
    ----------
    formation, seed, size, n_robots, graph : as :func:`data_synth.render`
    steps : int >= 1
    speed : float — metres per step along ``+x`` (``0`` keeps the formation still: every step
        renders the same poses with fresh sensor noise)
    switching, p_up, window : the per-step graph (module docstring)

    Frames are rendered, not read from the render cache (:mod:`data_synth.cache` holds
    snapshots).

    Raises
    ------
    InputError
        As :func:`data_synth.render`; ``steps < 1``; a speed that is not a finite number
        from 0 to ``MAX_SPEED``; ``p_up`` not a number in ``(0, 1]``; ``window`` not an integer >= 1;
        ``switching`` not a bool; frames that would hold more than the machine's memory.
    """
    steps = check_int(steps, "steps", 1)
    seed = check_int(seed, "seed", 0)  # a Python int: numpy's int64 wraps in seed * 1000
    if not _is_real(speed) or not np.isfinite(speed) or not 0 <= speed <= MAX_SPEED:
        raise InputError(f"speed {speed!r}: expected metres per step, a finite number >= 0 "
                         f"and at most {MAX_SPEED:g}")
    if not _is_real(p_up) or not 0 < p_up <= 1:
        raise InputError(f"p_up {p_up!r}: expected a probability in (0, 1]")
    window = check_int(window, "window", 1)
    if not isinstance(switching, (bool, np.bool_)):
        raise InputError(f"switching {switching!r}: expected True or False")
    name, kind, n, (W, H), centres, poses, edges, K = formation_setup(formation, seed, size, n_robots,
                                                             graph)
    held = steps * n * W * H * BYTES_PER_FRAME_PIXEL
    if held > _physical_memory():
        raise InputError(f"steps {steps}: {steps * n} frames of {W}x{H} would hold about "
                         f"{held / 1e9:.3g} GB, more than this machine's memory; fewer steps, "
                         "fewer robots or a smaller size")
    scene = build_scene(seed)
    views, all_centres = [], []
    for k in range(steps):
        shift = np.array([speed * (k - (steps - 1) / 2), 0.0, 0.0])
        for i, (R, t) in enumerate(poses):
            t_k = t - R @ shift  # same orientation, centre moved by `shift`
            image, depth = render_view(scene, K, R, t_k, (W, H),
                                       rng=np.random.default_rng([seed, 3, i, k]))
            views.append(View(name=f"r{i:02d}k{k:03d}", image=image, K=K.copy(), R=R.copy(),
                              t=t_k, depth=depth, intrinsics_known=True))
            all_centres.append(centres[i] + shift)
    if switching:
        from pipeline.transport.simulated import recurrent_topology

        topo = recurrent_topology(edges, p_up=p_up, window=window, seed=seed)
        step_edges = [topo(k) for k in range(steps)]
    else:
        step_edges = [edges.copy() for _ in range(steps)]
    flat = Formation(name=f"{name}-moving", views=views, comm_edges=edges, graph=kind,
                     seed=seed, centres=np.asarray(all_centres))
    return Sequence(name=name, n_robots=n, steps=steps, comm_edges=edges,
                    step_edges=step_edges, flat=flat, speed=float(speed))
