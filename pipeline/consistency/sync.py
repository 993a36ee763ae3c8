"""Distributed multi-way matching (``sync``): a cycle-consistent association agreed by merging.

The robots assign every feature to a *cluster* (a landmark of the universe, its size unknown
and found by the merging) so that no cluster holds two features of one camera (Def. 2.4):
the association is cycle-consistent by construction, with no detection (Sec. III) and no
memory beyond the robots' links. The clustering is the constrained greedy merge of QuickMatch
(Tron et al., ICCV W 2017) and of the evidence rule (:func:`.evidence.evidence_cut`): in order
of decreasing evidence, a link joins its two clusters unless they share a camera; a link is
kept iff its two ends end in one cluster. The centralized greedy merge visits the links one
at a time; here the robots reach the *same* clusters with Borůvka phases of *locally
dominant* links (the idea of Hoepman's distributed greedy matching, 2004):

Weights (Sec. "evidence" of the rule; both ends of a link compute the same value)
    ``w = λ + TRIANGLE_WEIGHT · τ``: ``λ`` the link's local log-likelihood ratio
    (:mod:`pipeline.link_evidence`, held by both robots of the link since matching), ``τ``
    the number of third cameras in which both ends match one common feature. Phase 0
    (*support*, one round): every robot sends each linked neighbour the other ends of its
    features linked to it; both ends of a link then count ``τ`` from the same two lists.
    Order: ``(w, -lo, -hi)`` decreasing (``lo < hi`` the link's global feature ids), a strict
    total order every robot evaluates alike.

A Borůvka round (two phases, each ended when nothing is in flight)
    A. *exchange and best.* Every robot sends, for each own feature with an *open* link (its
       two ends in different clusters, not yet found ineligible), the feature's cluster label
       and the cluster's camera set (a bit set of ``n`` bits) to the neighbour at the other
       end. An open link is *eligible* iff the two camera sets are disjoint; an ineligible
       link stays ineligible (camera sets only grow), so it is closed for good. Each robot
       takes, per own cluster, its best eligible link, and the clusters' members flood the
       maximum along the links inside the cluster (max-flood; a cluster has at most one
       feature per camera, so the flood crosses at most ``|cluster| - 1`` robot hops).
    B. *merge.* The ends of each cluster's best link tell each other their cluster's best.
       A link that is the best of *both* its clusters (locally dominant) merges them: label
       ``min(A, B)`` (the smallest global feature id of the cluster), camera set ``A ∪ B``.
       Each end floods the relabel inside its old cluster. A cluster has one best link, so
       it merges at most once per round: the merges of one round are disjoint pairs, each
       conflict-free.
    The stage ends after a phase A in which no robot holds an eligible link.

Why the result equals the centralized greedy merge (with the same weights and order)
    Induction on the merges. A locally dominant link ``e`` between ``A`` and ``B`` is the
    heaviest eligible link touching ``A`` or ``B``. The sequential greedy merge, run on the
    same clusters, reaches ``e`` before any other link touching ``A`` or ``B`` that is still
    eligible, and the links it takes before ``e`` neither touch ``A`` nor ``B`` nor change their
    camera sets, so ``e`` is still eligible there: it merges ``A`` and ``B`` too. Merging the
    disjoint dominant pairs of a round in any order therefore gives the greedy merge's
    clusters, and the heaviest eligible link of the whole team is always dominant, so every
    round with an eligible link merges at least one pair (at most ``m - 1`` rounds).
    ``tests/pipeline/consistency/test_sync.py`` checks the equality against an independent
    sequential implementation on random instances (Hypothesis).

Bounds and cost
    Rounds per Borůvka round ``≤ 2 (s + 1)`` with ``s`` the largest cluster's robot-diameter
    (``≤ n - 1``); memory per robot ``O(L_i + n/8 · clusters it sees)`` (its links, the labels
    of their far ends and the camera bit sets): it follows the links, never ``Σ |C|²``.
    Messages: phase 0 sends each feature's link list once per linked neighbour
    (``Σ_f deg(f)²`` ids in all); phase A, labels and camera sets of the open links only.

Missing links are not invented: a kept association set is connected by input links; the
pairs it implies between its features (the closure) are the association's output.

Payloads (counted at their numpy ``nbytes``): ``sync-support`` ``feat`` (F,) int32, ``deg``
(F,) int32, ``gid`` (D,) int64; ``sync-x`` ``feat`` (F,) int32, ``lab`` (F,) int32 (index into
``label``), ``label`` (U,) int64, ``cams`` (U, ⌈n/8⌉) uint8; ``sync-best`` ``label`` (K,) int64,
``w`` (K,) float64, ``lo``/``hi`` (K,) int64; ``sync-merge`` ``label``, ``w``, ``lo``, ``hi``
as for ``sync-best``; ``sync-relabel`` ``old`` (K, 2) int64, ``new`` (K,) int64, ``cams``
(K, ⌈n/8⌉) uint8.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pipeline.consistency.evidence import TRIANGLE_WEIGHT
from pipeline.consistency.robot import Robot
from pipeline.transport import Message, Transport

__all__ = ["SyncState", "equip_sync", "equip_robot", "start_support", "support_step", "start_exchange",
           "exchange_step", "start_merge", "merge_step", "finish_sync", "has_best",
           "run_sync", "greedy_merge", "CASE_SYNC", "SUPPORT", "EXCHANGE", "MERGE"]

Send = Callable[[int, str, dict], None]

#: deletion-log code of a link cut by the ``sync`` rule (next to Alg. 1's and the evidence rule's)
CASE_SYNC = 6
SUPPORT, EXCHANGE, MERGE = "sync-support", "sync-exchange", "sync-merge"
# a best link as a comparable key: larger is better (weight, then the smaller ends)
Key = tuple[float, int, int]


@dataclass
class SyncState:
    """What one robot holds for the ``sync`` rule (its own links only).

    Attributes
    ----------
    weight : (L,) float64 — local evidence ``λ`` of its links (link table order)
    w : (L,) float64 — ``λ + TRIANGLE_WEIGHT · τ`` once the support round is over
    lo, hi : (L,) int64 — the link's global feature ids, ``lo < hi``
    label : (m,) int64 — cluster of each own feature (smallest global id of the cluster)
    other : (L,) int64 — cluster of each link's far end, as last heard
    open : (L,) bool — ends in different clusters and not found ineligible
    heard : (L,) bool — the far end's cluster was heard in this phase A
    tree : (L,) bool — the link merged two clusters (the cluster's spanning tree)
    tau : (L,) int64 — triangle support counted so far (support round)
    cams : dict label -> int — camera bit sets of the clusters it knows
    best : dict label -> Key — best eligible link known for each own cluster (phase A)
    relabels : set — merges ``(A, B)`` applied in this phase B
    rounds : int — Borůvka rounds taken
    """

    weight: np.ndarray
    w: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    label: np.ndarray
    other: np.ndarray
    open: np.ndarray
    heard: np.ndarray
    tree: np.ndarray
    tau: np.ndarray
    nbytes_cams: int
    cams: dict = field(default_factory=dict)
    best: dict = field(default_factory=dict)
    relabels: set = field(default_factory=set)
    rounds: int = 0

    def nbytes(self) -> int:
        arrays = (self.weight, self.w, self.lo, self.hi, self.label, self.other, self.open,
                  self.heard, self.tree, self.tau)
        return (int(sum(a.nbytes for a in arrays)) + len(self.cams) * (8 + self.nbytes_cams)
                + 32 * len(self.best) + 16 * len(self.relabels))


def equip_sync(robot: Robot, link_weight) -> None:
    """Give a robot its ``sync`` state: the local evidence of its link table rows."""
    w = np.asarray(link_weight, dtype=np.float64).reshape(-1)
    own = robot.gid0 + robot.link_r.astype(np.int64)
    far = robot.offsets[robot.link_nbr] + robot.link_s.astype(np.int64)
    gid = robot.gid0 + np.arange(robot.m, dtype=np.int64)
    L = w.shape[0]
    robot.sync = SyncState(weight=w, w=w.copy(), lo=np.minimum(own, far), hi=np.maximum(own, far),
                           label=gid, other=far.copy(), open=robot.link_alive.copy(),
                           heard=np.zeros(L, dtype=bool), tree=np.zeros(L, dtype=bool),
                           tau=np.zeros(L, dtype=np.int64), nbytes_cams=(robot.n + 7) // 8)
    for g in gid.tolist():
        robot.sync.cams[g] = 1 << robot.id
    for g, j in zip(far.tolist(), robot.link_nbr.tolist(), strict=True):
        robot.sync.cams[g] = 1 << j


def equip_robot(robot: Robot, link_weight, keypoints=None, projection=None) -> None:
    """The registry's ``equip`` (:mod:`.rules`): the rule uses the links' evidence only."""
    equip_sync(robot, link_weight)


def _measure(robot: Robot) -> None:
    robot.peak_memory_bytes = max(robot.peak_memory_bytes,
                                  robot.fixed_bytes() + robot.sync.nbytes())


def _to_bytes(bits: int, nb: int) -> np.ndarray:
    return np.frombuffer(bits.to_bytes(nb, "little"), dtype=np.uint8)


def _from_bytes(row: np.ndarray) -> int:
    return int.from_bytes(np.ascontiguousarray(row, dtype=np.uint8).tobytes(), "little")


# --------------------------------------------------------------------------- phase 0: support


def start_support(robot: Robot, send: Send) -> None:
    """Send each linked neighbour the far ends of every own feature linked to it."""
    alive = robot.link_alive
    far = robot.offsets[robot.link_nbr] + robot.link_s.astype(np.int64)
    for j in np.unique(robot.link_nbr[alive]).tolist():
        feats = np.unique(robot.link_r[alive & (robot.link_nbr == j)])
        sel = alive & np.isin(robot.link_r, feats)
        order = np.argsort(robot.link_r[sel], kind="stable")
        r_sel = robot.link_r[sel][order]
        deg = np.bincount(np.searchsorted(feats, r_sel), minlength=feats.size)
        send(j, SUPPORT, {"feat": feats.astype(np.int32), "deg": deg.astype(np.int32),
                          "gid": far[sel][order]})
    _measure(robot)


def support_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """Count each link's triangle support ``τ`` from the far end's list; set ``w``."""
    st = robot.sync
    alive = robot.link_alive
    far = robot.offsets[robot.link_nbr] + robot.link_s.astype(np.int64)
    m_total = np.int64(robot.m_total)
    own_keys = np.sort(robot.link_r[alive].astype(np.int64) * m_total + far[alive])
    tau = st.tau  # accumulated: on a reliable channel the lists may arrive in several rounds
    for msg in inbox:
        if msg.kind != SUPPORT:
            continue
        p = msg.payload
        feats, deg, gid = p["feat"].astype(np.int64), p["deg"].astype(np.int64), p["gid"]
        starts = np.concatenate([[0], np.cumsum(deg)])
        links = np.flatnonzero(alive & (robot.link_nbr == msg.src))
        if links.size == 0:
            continue
        pos = np.searchsorted(feats, robot.link_s[links])
        ok = (pos < feats.size) & (feats[np.minimum(pos, feats.size - 1)] == robot.link_s[links])
        links, pos = links[ok], pos[ok]
        counts = deg[pos]
        rep = np.repeat(links, counts)
        idx = np.repeat(starts[pos], counts) + (np.arange(counts.sum())
                                                - np.repeat(np.cumsum(counts) - counts, counts))
        keys = robot.link_r[rep].astype(np.int64) * m_total + gid[idx]
        hit = np.isin(keys, own_keys, assume_unique=False)
        np.add.at(tau, rep[hit], 1)
    st.w = st.weight + TRIANGLE_WEIGHT * tau
    _measure(robot)


# --------------------------------------------------------------------------- phase A


def start_exchange(robot: Robot, send: Send) -> None:
    """Phase A, round 0: tell the far end of every open link the own end's cluster."""
    st = robot.sync
    st.best = {}
    st.heard[:] = False
    st.open &= robot.link_alive
    nb = st.nbytes_cams
    for j in np.unique(robot.link_nbr[st.open]).tolist():
        feats = np.unique(robot.link_r[st.open & (robot.link_nbr == j)])
        labels, lab = np.unique(st.label[feats], return_inverse=True)
        cams = np.stack([_to_bytes(st.cams[int(g)], nb) for g in labels.tolist()])
        send(j, "sync-x", {"feat": feats.astype(np.int32), "lab": lab.astype(np.int32),
                           "label": labels.astype(np.int64), "cams": cams})
    _measure(robot)


def _internal(robot: Robot, label: int) -> np.ndarray:
    """Neighbours this robot shares a tree link of cluster ``label`` with (the links that
    merged it: the cluster's spanning tree, along which its floods travel)."""
    st = robot.sync
    sel = st.tree & (st.label[robot.link_r] == label)
    return np.unique(robot.link_nbr[sel])


def _send_best(robot: Robot, labels: list[int], send: Send, skip: int = -1) -> None:
    st = robot.sync
    out: dict[int, list[int]] = {}
    for g in labels:
        for j in _internal(robot, g).tolist():
            if j != skip:
                out.setdefault(j, []).append(g)
    for j, gs in out.items():
        keys = [st.best[g] for g in gs]
        send(j, "sync-best", {"label": np.array(gs, dtype=np.int64),
                              "w": np.array([k[0] for k in keys], dtype=np.float64),
                              "lo": np.array([-k[1] for k in keys], dtype=np.int64),
                              "hi": np.array([-k[2] for k in keys], dtype=np.int64)})


def exchange_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """Phase A: take the far ends' clusters, judge eligibility, max-flood the best link."""
    st = robot.sync
    fresh = np.zeros(robot.link_r.shape[0], dtype=bool)
    improved: dict[int, bool] = {}
    for msg in inbox:
        p = msg.payload
        if msg.kind == "sync-x":
            labels = p["label"].astype(np.int64)
            for g, row in zip(labels.tolist(), p["cams"], strict=True):
                st.cams[g] = _from_bytes(row)
            link = robot.find_links(np.full(p["feat"].shape, msg.src), p["feat"])
            ok = link >= 0
            link = link[ok]
            st.other[link] = labels[p["lab"][ok]]
            st.heard[link] = True
            fresh[link] = True
        elif msg.kind == "sync-best":
            for g, w, lo, hi in zip(p["label"].tolist(), p["w"].tolist(), p["lo"].tolist(),
                                    p["hi"].tolist(), strict=True):
                key = (w, -lo, -hi)
                if g in st.best and st.best[g] >= key:
                    continue
                st.best[g] = key
                improved[g] = True
    if fresh.any():
        own = st.label[robot.link_r]
        inside = fresh & (own == st.other)
        st.open[inside] = False
        cand = np.flatnonzero(fresh & st.open)
        for k in cand.tolist():
            a, b = int(own[k]), int(st.other[k])
            if st.cams[a] & st.cams[b]:
                st.open[k] = False  # Def. 2.4: the merge would join two features of a camera
                continue
            key = (float(st.w[k]), -int(st.lo[k]), -int(st.hi[k]))
            if a not in st.best or key > st.best[a]:
                st.best[a] = key
                improved[a] = True
    if improved:
        _send_best(robot, sorted(improved), send)
    _measure(robot)


def has_best(robot: Robot) -> bool:
    """After phase A: does some own cluster hold an eligible link?"""
    return bool(robot.sync.best)


# --------------------------------------------------------------------------- phase B


def _own_best_links(robot: Robot) -> list[tuple[int, int]]:
    """``(own cluster, link index)`` for every own cluster whose best link is an own link."""
    st = robot.sync
    out = []
    own = st.label[robot.link_r]
    for g, key in st.best.items():
        lo, hi = -key[1], -key[2]
        k = np.flatnonzero((st.lo == lo) & (st.hi == hi) & (own == g))
        if k.size:
            out.append((g, int(k[0])))
    return out


def start_merge(robot: Robot, send: Send) -> None:
    """Phase B, round 0: tell the far end of each own cluster's best link that it is."""
    st = robot.sync
    st.relabels = set()
    out: dict[int, list[tuple[int, int]]] = {}
    for g, k in _own_best_links(robot):
        out.setdefault(int(robot.link_nbr[k]), []).append((g, k))
    for j, items in out.items():
        keys = [st.best[g] for g, _ in items]
        send(j, "sync-merge", {"label": np.array([g for g, _ in items], dtype=np.int64),
                               "w": np.array([k[0] for k in keys], dtype=np.float64),
                               "lo": np.array([-k[1] for k in keys], dtype=np.int64),
                               "hi": np.array([-k[2] for k in keys], dtype=np.int64)})
    _measure(robot)


def _apply_relabel(robot: Robot, a: int, b: int, new: int, cams: int, send: Send,
                   skip: int = -1) -> None:
    """Clusters ``a`` and ``b`` are one, named ``new``: update and flood inside the old one."""
    st = robot.sync
    if (a, b) in st.relabels:
        return
    st.relabels.add((a, b))
    targets: set[int] = set()
    for g in (a, b):
        targets.update(_internal(robot, g).tolist())
    mine = (st.label == a) | (st.label == b)
    st.label[mine] = new
    st.other[(st.other == a) | (st.other == b)] = new
    st.cams[new] = cams
    for j in sorted(targets - {skip}):
        send(j, "sync-relabel", {"old": np.array([[a, b]], dtype=np.int64),
                                 "new": np.array([new], dtype=np.int64),
                                 "cams": _to_bytes(cams, st.nbytes_cams)[None, :]})


def merge_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """Phase B: merge along locally dominant links; flood the relabels."""
    st = robot.sync
    for msg in inbox:
        p = msg.payload
        if msg.kind == "sync-merge":
            for b, w, lo, hi in zip(p["label"].tolist(), p["w"].tolist(), p["lo"].tolist(),
                                    p["hi"].tolist(), strict=True):
                k = np.flatnonzero((st.lo == lo) & (st.hi == hi))
                if k.size == 0:
                    continue
                a = int(st.label[robot.link_r[k[0]]])
                if st.best.get(a) != (w, -lo, -hi):
                    continue  # not the best of this end's cluster: not dominant
                x, y = min(a, b), max(a, b)
                _apply_relabel(robot, x, y, x, st.cams[a] | st.cams[b], send)
                st.tree[k[0]] = True  # after the flood inside the old cluster: not back
        elif msg.kind == "sync-relabel":
            for (a, b), new, row in zip(p["old"].tolist(), p["new"].tolist(), p["cams"],
                                        strict=True):
                _apply_relabel(robot, a, b, new, _from_bytes(row), send, skip=msg.src)
    _measure(robot)


def finish_sync(robot: Robot, round_: int) -> None:
    """Cut every own link whose two ends ended in different clusters; name the tracks."""
    st = robot.sync
    cut = robot.link_alive & (st.label[robot.link_r] != st.other)
    k = np.flatnonzero(cut)
    robot.link_alive[k] = False
    robot.deleted_round[k] = round_
    robot.deleted_case[k] = CASE_SYNC
    robot.deleted_iteration[k] = robot.iteration
    has_link = np.zeros(robot.m, dtype=bool)
    has_link[robot.link_r[robot.link_alive]] = True
    robot.component = np.where(has_link, st.label, -1)
    _measure(robot)


# --------------------------------------------------------------------------- simulator driver


def _phase(robots: list[Robot], network: Transport, start, step, on_round, t0: int,
           cap: int) -> int:
    """One phase on every robot until nothing is in flight; returns the rounds taken."""
    sends = [lambda dst, kind, p, i=rb.id: network.send(i, dst, kind, p) for rb in robots]
    for rb in robots:
        start(rb, sends[rb.id])
    t = 0
    while network.pending:
        network.end_round()
        t += 1
        if on_round is not None:
            on_round(t0 + t)
        receivers = network.receivers() if hasattr(network, "receivers") else range(len(robots))
        for i in receivers:
            step(robots[i], network.inbox(i), sends[i], t0 + t)
        if t > cap:
            raise RuntimeError(f"sync phase did not end within {cap} rounds")
    return t


def run_sync(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """The ``sync`` rule on every robot (each equipped by :func:`equip_sync`): support round,
    Borůvka rounds until no eligible link is left, then each robot cuts its side.

    The driver only plays the clock and the phase barrier (nothing in flight) and reads one
    bit per robot (:func:`has_best`), as the termination wave of a robot alone would.

    Returns ``rounds``, ``boruvka_rounds`` and ``support_rounds``.
    """
    n = len(robots)
    cap = 2 * n + 4
    t = _phase(robots, network, start_support, support_step, on_round, 0, cap)
    support_rounds = t
    boruvka = 0
    m_total = robots[0].m_total if robots else 0
    while True:
        t += _phase(robots, network, start_exchange, exchange_step, on_round, t, cap)
        if not any(has_best(rb) for rb in robots):
            break
        boruvka += 1
        if boruvka > m_total:
            raise RuntimeError(f"sync did not end within {m_total} Borůvka rounds")
        t += _phase(robots, network, start_merge, merge_step, on_round, t, cap)
    for rb in robots:
        rb.sync.rounds = boruvka
        finish_sync(rb, t)
    return dict(rounds=t, boruvka_rounds=boruvka, support_rounds=support_rounds)


# --------------------------------------------------------------------------- reference


def greedy_merge(m_total: int, a, b, cam_a, cam_b, w) -> np.ndarray:
    """Cluster label of every feature after the sequential constrained greedy merge.

    Links ``(a[k], b[k])`` (global ids, cameras ``cam_a``, ``cam_b``) in decreasing
    ``(w, -min, -max)``; a link joins its two clusters unless they share a camera. Labels are
    the smallest global id of each cluster. The centralized counterpart of :func:`run_sync`.
    """
    a, b = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((hi, lo, -np.asarray(w, dtype=np.float64)))
    parent = np.arange(m_total)
    cams: dict[int, int] = {}
    cam_of = np.full(m_total, -1, dtype=np.int64)
    cam_of[a] = cam_a
    cam_of[b] = cam_b

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = int(parent[x])
        return x

    for k in order.tolist():
        x, y = find(int(lo[k])), find(int(hi[k]))
        if x == y:
            continue
        cx = cams.get(x, 1 << int(cam_of[x]) if cam_of[x] >= 0 else 0)
        cy = cams.get(y, 1 << int(cam_of[y]) if cam_of[y] >= 0 else 0)
        if cx & cy:
            continue
        x, y = min(x, y), max(x, y)
        parent[y] = x
        cams[x] = cx | cy
    return np.array([find(x) for x in range(m_total)], dtype=np.int64)
