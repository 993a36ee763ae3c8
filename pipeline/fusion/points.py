"""The fused landmark of every track, from the robots' final estimates (reporting).

After dynamic voting (Montijano et al., Sec. IV-B) every robot that observes a track holds
its own estimate of the track's landmark and the hypothesis it voted for. The fused point of
a track is formed from the largest connected group of its observers (in the track's
observer graph) that hold a valid estimate, among them those that picked the group's most
common winner, averaged. Ties are broken by index: of two equally large groups the one
holding the lowest robot id, of two equally common winners the lowest hypothesis. Both the
simulator's stage (:func:`pipeline.fusion.landmarks.fuse_tracks`) and the observer of a team of robot processes
(:func:`pipeline.team.assemble.fusion_of_team`) form it here, from the same arrays.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

__all__ = ["FusedPoints", "fused_points"]


class FusedPoints:
    """The fused landmarks of ``B`` tracks observed by ``n`` robots.

    Attributes
    ----------
    points : (B, 3) float — the fused point of each track (zeros where none)
    has_point : (B,) bool — the track has a fused point
    group : (B, n) bool — the robots whose estimates were averaged
    split : (B,) bool — the group's robots picked more than one winner (a tie of votes)
    """

    def __init__(self, points, has_point, group, split) -> None:
        self.points, self.has_point, self.group, self.split = points, has_point, group, split


def fused_points(node_edges: np.ndarray, good: np.ndarray, theta: np.ndarray,
                 winner: np.ndarray, n_winners: int | None = None) -> FusedPoints:
    """The fused point of each track (module docstring).

    Parameters
    ----------
    node_edges : (E, 2) int — edges of the observer graphs, nodes ``track * n + robot``
    good : (B, n) bool — the robot holds a valid estimate of the track
    theta : (B, n, 3) float — each robot's final estimate
    winner : (B, n) int — the hypothesis each robot picked
    n_winners : int or None — number of hypotheses (default ``winner.max() + 1``)

    Returns
    -------
    FusedPoints
    """
    B, n = good.shape
    ncomp, lab = connected_components(
        sp.csr_matrix((np.ones(len(node_edges)), (node_edges[:, 0], node_edges[:, 1])),
                      shape=(B * n, B * n)), directed=False)
    lab = lab.reshape(B, n)
    size = np.bincount(lab[good], minlength=ncomp)
    score = np.where(good, size[lab], -1)
    best_node = np.argmax(score, axis=1) if B else np.zeros(0, np.int64)
    has_pt = score[np.arange(B), best_node] > 0
    grp = good & (lab == lab[np.arange(B), best_node][:, None]) & has_pt[:, None]
    K = int(winner.max(initial=0)) + 1 if n_winners is None else int(n_winners)
    wcount = np.zeros((B, K), dtype=np.int64)
    gb, gi = np.nonzero(grp)
    np.add.at(wcount, (gb, winner[gb, gi]), 1)
    split = (wcount > 0).sum(1) > 1
    grp &= winner == np.argmax(wcount, axis=1)[:, None]
    cnt = grp.sum(1)
    pts = (theta * grp[..., None]).sum(1) / np.maximum(cnt, 1)[:, None]
    return FusedPoints(pts, has_pt, grp, split)
