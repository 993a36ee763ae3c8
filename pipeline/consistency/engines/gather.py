"""The sets of an online step solved at their roots (step 2b of :mod:`.online`).

A set of at most ``B`` features that a step's new links touch is solved by the evidence
rule's merge at one robot, its *root* (the robot of the member :func:`.roots.root_of` picks
from the set list every member holds; the root's tokens flood the set one hop per round, so
the neighbour a robot's first token came from is a parent on a shortest path). Its
robots send their bundles (:mod:`pipeline.consistency.evidence`, step 1: each feature's
keypoint, its links with their evidence weights, its frame's projection) up that tree; the
root solves what :func:`~pipeline.consistency.evidence.solve_set` solves on them (the weights
of :func:`~pipeline.consistency.evidence.set_problem`, here
:func:`~pipeline.consistency.evidence.set_weights` for all sets
at once, then :func:`~pipeline.consistency.evidence.evidence_cut`: the Kruskal merge by
decreasing evidence with the geometric test) and sends the cut links back down; each robot
cuts its side. The same bundles give the same cuts as the rule's own flood of them to every
robot of the set; one path per bundle and back costs far fewer bytes than every bundle over
every link of the set.

Counts: a bundle, ``128 + 16 deg`` bytes (the rule's bundle fields), one message per hop up
the shortest-path tree to the root (no two bundles share a message: a bound); the cut links,
16 bytes each, one message down each tree edge; ``2 ecc(root) + 1`` rounds. Hops are counted
between features: in a conflict-free set (one feature per image) that is the image graph, an
image being a robot of the stage; in a conflictive set a robot may hold two features of a
path, so the count bounds the hops between robots. A robot holds at most its set's bundles
(the root all of them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from pipeline.consistency.engines.phases import run_quiet_phase
from pipeline.consistency.robot import Robot
from pipeline.consistency.roots import roots_step, spread, start_roots
from pipeline.transport import HEADER_BYTES

__all__ = ["RootSolution", "run_roots", "solve_at_roots"]


@dataclass
class RootSolution:
    """What :func:`solve_at_roots` decided and what it cost.

    ``links`` (E,) the indices of the solved links in the caller's link arrays, grouped by
    set; ``set_of`` (E,) each link's set; ``a``, ``b`` (E,) its ends (smaller first);
    ``cut`` (E,) bool; ``sets`` the solved sets, ascending; ``rounds``, ``messages``,
    ``nbytes`` of the gathering; ``held`` (cameras,) the bundle bytes each camera holds at most:
    the sum over the sets it has a feature in of the set's bundle bytes, each set once."""

    links: np.ndarray
    set_of: np.ndarray
    a: np.ndarray
    b: np.ndarray
    cut: np.ndarray
    sets: np.ndarray
    rounds: int
    messages: int
    nbytes: int
    held: np.ndarray


def solve_at_roots(sub, cam, a_all, b_all, q_all, on, comp, kp, P_cam, unposed, sent,
                   n_cams: int) -> RootSolution:
    """Solve the sets of the links ``on`` at their roots (module docstring).

    Parameters
    ----------
    sub : (F,) int — the stage's features (global ids), ascending
    cam : (F,) int — each feature's camera in the stage
    a_all, b_all, q_all : (L,) — the stage's links (global ids) and their quality
    on : (L,) bool — the links of the sets to solve
    comp : (F,) int — each feature's set
    kp : (F, 2) float — each feature's keypoint; ``P_cam`` (cameras, 3, 4) each camera's
        projection (any value for a camera of unknown pose)
    unposed : sets with a camera of unknown pose: solved without the geometric test
    sent : (L,) bool — links whose cut is sent back (a cut history link is not)
    n_cams : int — cameras of the stage
    """
    from pipeline.consistency.evidence import evidence_cut, set_weights
    from pipeline.matching.link_evidence import ratio_llr

    ia = np.searchsorted(sub, a_all)
    ks = np.flatnonzero(on)
    ks = ks[np.argsort(comp[ia[ks]], kind="stable")]   # grouped by set
    lc = comp[ia[ks]]
    a, b = np.minimum(a_all[ks], b_all[ks]), np.maximum(a_all[ks], b_all[ks])
    sa, sb = np.searchsorted(sub, a), np.searchsorted(sub, b)
    ca, cb = cam[sa], cam[sb]
    local = ratio_llr(1.0 - np.asarray(q_all, np.float64)[ks])
    c_w, c_head = np.unique(lc, return_index=True)
    c_end = np.r_[c_head[1:], len(lc)]
    geometric = ~np.isin(lc, unposed)                 # the set's images all posed
    w = set_weights(a, b, ca, cb, local,
                    lambda ids: kp[np.searchsorted(sub, ids)],
                    lambda ids: P_cam[cam[np.searchsorted(sub, ids)]], geometric=geometric)
    cut = np.zeros(len(ks), bool)
    for u, v in zip(c_head.tolist(), c_end.tolist(), strict=True):
        kpd = Pd = None
        if geometric[u]:
            f = np.unique(np.r_[sa[u:v], sb[u:v]])
            kpd = dict(zip(sub[f].tolist(), kp[f], strict=True))
            Pd = dict(zip(sub[f].tolist(), P_cam[cam[f]], strict=True))
        cut[u:v] = evidence_cut(a[u:v], b[u:v], ca[u:v], cb[u:v], w[u:v], kpd, Pd)
    # the counts of the gathering (module docstring)
    n_s = len(sub)
    adj = sp.coo_matrix((np.ones(2 * len(sa), bool), (np.r_[sa, sb], np.r_[sb, sa])),
                        shape=(n_s, n_s)).tocsr()
    f_set = np.unique(np.stack([np.r_[lc, lc], np.r_[sa, sb]], axis=1), axis=0)
    f_c = np.searchsorted(c_w, f_set[:, 0])            # each member's set
    members = np.bincount(f_c, minlength=len(c_w))
    # each set's root: its member of smallest spread (roots.root_of), first of its rows
    by_key = np.lexsort((spread(sub[f_set[:, 1]]), f_c))
    root = f_set[by_key[np.r_[0, np.cumsum(members)[:-1]]], 1]
    dist = np.full(n_s, -1, np.int64)
    dist[root] = 0
    front, d = root, 0
    while len(front):
        d += 1
        nxt = np.unique(adj[front].indices)
        front = nxt[dist[nxt] < 0]
        dist[front] = d
    f_dist = dist[f_set[:, 1]]
    ecc = np.zeros(len(c_w), np.int64)
    np.maximum.at(ecc, f_c, f_dist)
    deg = np.bincount(np.r_[sa, sb], minlength=n_s)
    f_bytes = 128 + 16 * deg[f_set[:, 1]]
    bundle_c = np.bincount(f_c, weights=f_bytes, minlength=len(c_w)).astype(np.int64)
    cuts_c = np.bincount(np.searchsorted(c_w, lc[cut & sent[ks]]), minlength=len(c_w))
    rounds = int((2 * ecc + 1).max(initial=0))
    msgs = int(f_dist.sum() + (members - 1).sum())
    nbytes = int((f_bytes * f_dist).sum() + (16 * cuts_c * (members - 1)).sum()) \
        + HEADER_BYTES * msgs
    # a camera holds at most its set's bundles, once per set however many of its features
    # the set has (a conflictive set may have two of one image)
    cam_set = np.unique(np.stack([cam[f_set[:, 1]], f_c], axis=1), axis=0).reshape(-1, 2)
    held = np.bincount(cam_set[:, 0], weights=bundle_c[cam_set[:, 1]], minlength=n_cams)
    return RootSolution(links=ks, set_of=lc, a=a, b=b, cut=cut, sets=c_w, rounds=rounds,
                        messages=msgs, nbytes=nbytes, held=held)


def run_roots(robots: list[Robot], network, on_round=None, t0: int = 0) -> dict:
    """The protocol on every robot of the simulator, each on its own inbox, until nothing is
    in flight (the end a robot alone learns from the termination wave). Returns ``rounds``,
    ``sets`` (solved, counted at their roots); RuntimeError if a set stayed unsolved."""
    rooted = []
    t = run_quiet_phase(robots, network, lambda rb, send: rooted.append(start_roots(rb, send)),
                        roots_step, on_round, t0, cap=3 * len(robots) + 6, what="roots")
    left = [rb.id for rb in robots if set(rb.roots.own) - rb.roots.answered]
    if left:
        raise RuntimeError(f"robots {left} did not learn the solution of all their sets")
    return dict(rounds=t, sets=int(sum(rooted)))
