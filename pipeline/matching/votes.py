"""Distributed refinement of pairwise matches by two-hop votes.

Pairwise matching decides each pair of images from their two descriptor sets alone. A team
holds more evidence: if robot ``i`` matched its landmark ``r`` to ``t`` of a common
neighbour ``k``, and ``k`` matched ``t`` to ``s`` of ``j``, the path ``r → t → s`` is a vote
for the link ``(i, r)–(j, s)``. The vote matrix of an edge,

    ``W_ij = A_ij + Σ_{k ∈ N_i ∩ N_j} A_ik A_kj``        (paths of length ≤ 2, ``K_i × K_j``),

is one step of the power iteration behind permutation synchronization (Pachauri, Kondor,
Singh, "Solving the multi-way matching problem by permutation synchronization", NIPS 2013,
restricted to the paths a robot can see through its neighbours). As there, it is projected
back to a one-to-one matching by the Hungarian algorithm (maximum total votes), and a pair is
kept only when it holds a strict majority of the votes of its row and of its column — the
paths leaving ``r`` towards ``j`` and those reaching ``s`` from ``i`` mostly agree. Without
common neighbours (a ring) ``W_ij = A_ij`` and nothing changes.

Protocol (one iteration = two synchronous rounds, every message through the
:class:`~pipeline.transport.simulated.Network`, which counts messages and bytes):

1. every robot sends each neighbour its current matches with all its neighbours (kind
   ``matches``: neighbour ids ``(d,)`` and a table ``(d, K_i)`` of matched landmark ids,
   ``-1`` for none);
2. the lower-id robot of each edge computes ``W_ij`` from its own table and the tables it
   received, decides the new ``A_ij`` and sends it to the other end (kind ``decision``).

Robots see only their own tables and their inbox. Iterations repeat until a fixed point (an
iteration in which no edge's matches changed) or a cap (stated default 10). The fixed point
is noticed by the simulation, which sees every robot's change count — like the phase ends of
the consistency stage; a deployment would run the cap. The report lists how many matches
changed in each iteration.

Evidence of the refined links. The votes decide *which* pairs are matched; a refined link
keeps the quality its pair had in the input (``1 − ratio`` of the descriptor matching, held by
both robots of the link since matching, so both ends know it without a message), and a pair
the votes introduced, which the descriptor matching did not choose, gets quality 0 (ratio 1:
no better than another candidate). The vote share is not a quality: its paths of length 2 are
the triangles the ``evidence`` and ``sync`` rules count themselves, and on a graph with few
common neighbours (``ring2``: at most three voters per pair) nearly every kept pair has share
1, so a rule weighing the links would see all of them tied and decide by the order of the
feature ids. Measured (``bench/multiway.py --inputs guided+votes --renumber 1 2 3``: CMU
hotel, guided matching then votes, ``sync``, the same cameras numbered four ways on the same
``ring2`` graph): with the share as quality F1 0.986 / 0.821 / 0.897 / 0.677 on 101 frames
and 0.970 / 0.937 / 0.887 / 0.990 on 20 (the frames in ring order did well by the accident of
ids growing the clusters along the ring); with the input quality 0.997 and 0.990 for every
numbering.
"""

from __future__ import annotations

from functools import partial

import numpy as np
from scipy.optimize import linear_sum_assignment

from pipeline.errors import InputError
from pipeline.transport.simulated import Network
from pipeline.types import Links

__all__ = ["VoteRobot", "refine_by_votes", "DEFAULT_ITERATIONS"]

DEFAULT_ITERATIONS = 10


class VoteRobot:
    """One robot's state: its matches with each neighbour as a table.

    Attributes
    ----------
    id : int
    m : int — own landmark count ``K_i``
    nbrs : (d,) int64 — neighbour ids, ascending
    table : (d, m) int64 — ``table[a, r]`` = landmark of ``nbrs[a]`` matched to ``r``, ``-1``
    quality : (d, m) float64 — quality of each current match: its input quality where the
        input matched the same pair, else 0 (module notes)
    input_table, input_quality : (d, m) — the input matches and their quality (``-1`` / 0)
    """

    def __init__(self, i: int, m: int, nbrs: np.ndarray) -> None:
        self.id = int(i)
        self.m = int(m)
        self.nbrs = np.asarray(nbrs, dtype=np.int64)
        self.table = np.full((self.nbrs.size, self.m), -1, dtype=np.int64)
        self.quality = np.zeros((self.nbrs.size, self.m))
        self.input_table = self.table.copy()
        self.input_quality = np.zeros((self.nbrs.size, self.m))
        self.received: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.last_table: np.ndarray | None = None
        self.last_R: np.ndarray | None = None

    def slot(self, j: int) -> int:
        return int(np.searchsorted(self.nbrs, j))

    def send_matches(self, send) -> None:
        """Step 1: the whole table to every neighbour."""
        payload = {"nbrs": self.nbrs.astype(np.int32), "table": self.table.astype(np.int32)}
        for j in self.nbrs.tolist():
            send(j, "matches", payload)

    def decide(self, inbox, send, m_of: np.ndarray) -> int:
        """Step 2 for every edge this robot owns (``i < j``); returns matches changed.

        ``W_ij`` depends on the own tables and the received ones only; an edge none of whose
        inputs changed since the last iteration keeps its matches without recomputing.
        """
        received = {msg.src: (msg.payload["nbrs"].astype(np.int64),
                              msg.payload["table"])
                    for msg in inbox if msg.kind == "matches"}
        owned = self.nbrs[self.nbrs > self.id]
        if owned.size == 0:
            self.received, self.last_table = received, self.table.copy()
            return 0
        n_total = int(m_of.size)
        kmax = int(m_of.max())
        d = self.nbrs.size
        # R[a, j, t]: landmark of j that neighbour nbrs[a] matched to its landmark t
        R = np.full((d, n_total, kmax), -1, dtype=np.int32)
        got = [(a, received[k]) for a, k in enumerate(self.nbrs.tolist()) if k in received]
        if got:
            rows = np.concatenate([np.full(kn.size, a) for a, (kn, _) in got])
            cols = np.concatenate([kn for _, (kn, _) in got])
            tabs = [kt for _, (_, kt) in got]
            if all(kt.shape[1] == kmax for kt in tabs):
                block = np.concatenate(tabs)
            else:  # robots with fewer landmarks than the largest: pad their tables with -1
                block = np.full((rows.size, kmax), -1, dtype=np.int32)
                start = 0
                for kt in tabs:
                    block[start:start + kt.shape[0], :kt.shape[1]] = kt
                    start += kt.shape[0]
            R[rows, cols] = block
        # which (neighbour k -> robot j) tables changed since the last iteration
        prev = self.last_R
        dirty_kj = np.ones((d, n_total), dtype=bool) if prev is None or prev.shape != R.shape \
            else (prev != R).any(axis=2)
        self.last_R = R
        own_dirty = (self.last_table is None or self.last_table.shape != self.table.shape)
        own_changed = np.ones(d, dtype=bool) if own_dirty else \
            (self.last_table != self.table).any(axis=1)
        self.received, self.last_table = received, self.table.copy()
        # an edge (i, j) must be recomputed if A_ij, some A_ik or some A_kj changed
        any_own = bool(own_changed.any())
        todo = [j for j in owned.tolist()
                if any_own or dirty_kj[:, j].any()]
        if not todo:
            return 0
        todo = np.asarray(todo, dtype=np.int64)
        # S[a, j, r]: the landmark of j reached from own r through neighbour nbrs[a]
        t = self.table                                    # (d, m)
        aa, rr = np.nonzero(t >= 0)
        S = np.full((d, todo.size, self.m), -1, dtype=np.int32)
        S[aa, :, rr] = R[aa[:, None], todo[None, :], t[aa, rr][:, None]]
        # the path through j itself is the direct link, counted once below
        slots = np.searchsorted(self.nbrs, todo)
        S[slots, np.arange(todo.size), :] = -1
        a_idx, e_idx, r_idx = np.nonzero(S >= 0)
        s_idx = S[a_idx, e_idx, r_idx].astype(np.int64)
        W_all = np.bincount((e_idx * self.m + r_idx) * kmax + s_idx,
                            minlength=todo.size * self.m * kmax
                            ).reshape(todo.size, self.m, kmax).astype(np.float64)
        direct = self.table[slots]                        # (E, m): A_ij, the path of length 1
        e_d, r_d = np.nonzero(direct >= 0)
        W_all[e_d, r_d, direct[e_d, r_d]] += 1.0
        changed = 0
        for e, j in enumerate(todo.tolist()):
            b = int(slots[e])
            new = _project(W_all[e, :, :int(m_of[j])])
            changed += int((new != self.table[b]).sum())
            self.table[b] = new
            same = (new >= 0) & (new == self.input_table[b])
            self.quality[b] = np.where(same, self.input_quality[b], 0.0)
            rows = np.flatnonzero(new >= 0)
            send(j, "decision", {"src_feat": rows.astype(np.int32),
                                 "dst_feat": new[rows].astype(np.int32)})
        return changed

    def apply_decisions(self, inbox) -> None:
        """Take the matches decided by the lower-id end of each edge."""
        for msg in inbox:
            if msg.kind != "decision":
                continue
            b = self.slot(msg.src)
            self.table[b] = -1
            self.table[b, msg.payload["dst_feat"]] = msg.payload["src_feat"]
            same = (self.table[b] >= 0) & (self.table[b] == self.input_table[b])
            self.quality[b] = np.where(same, self.input_quality[b], 0.0)


def _project(W: np.ndarray) -> np.ndarray:
    """Hungarian on the votes, then the strict-majority test in row and column.

    Returns ``(K_i,)``: the matched landmark of each own landmark, or ``-1``.
    """
    match = np.full(W.shape[0], -1, dtype=np.int64)
    if W.size == 0 or not W.any():
        return match
    r, s = linear_sum_assignment(W, maximize=True)
    w = W[r, s]
    row, col = W.sum(axis=1)[r], W.sum(axis=0)[s]
    keep = (w > 0) & (2 * w > row) & (2 * w > col)
    match[r[keep]] = s[keep]
    return match


def refine_by_votes(features_per_camera, comm_edges, links: Links,
                    iterations: int = DEFAULT_ITERATIONS) -> tuple[Links, dict]:
    """Refine the matches of every communication edge by two-hop votes (module notes).

    Parameters
    ----------
    features_per_camera : (n,) int
    comm_edges : (E, 2) int, ``i < j``
    links : Links, (L,) — one-to-one per edge (Assumption 2.2)
    iterations : int >= 1 — cap; stops earlier at a fixed point

    Returns
    -------
    refined : Links — quality: the input quality of the pair, 0 for a pair the votes
        introduced (module notes)
    stats : dict — ``iterations`` (run), ``fixed_point`` (bool), ``rounds``, ``messages``, ``bytes``,
        ``changed_per_iteration`` (matches changed, counted at the deciding end)
    """
    from pipeline.association import camera_offsets, check_links
    from pipeline.commgraph import comm_edges_for

    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) \
            or iterations < 1:
        raise InputError(f"vote iterations {iterations!r}: expected a whole number >= 1")
    m = np.diff(camera_offsets(features_per_camera))
    n = m.size
    # the links as resolve_conflicts takes them (ids in range, one-to-one, cam_i < cam_j) and
    # on the comm graph (None: cameras sharing a link): a link off it was placed at another
    # neighbour's row and came back as a link the input never had
    check_links(links, m)
    edges = comm_edges_for(m, links, comm_edges)
    nbrs = [[] for _ in range(n)]
    for i, j in edges.tolist():
        nbrs[i].append(j)
        nbrs[j].append(i)
    robots = [VoteRobot(i, m[i], np.unique(np.asarray(nb, dtype=np.int64))) for i, nb in
              enumerate(nbrs)]
    # each robot's own matches (what its matching produced), at both ends of every link
    owner = np.concatenate([links.cam_i, links.cam_j])
    other = np.concatenate([links.cam_j, links.cam_i])
    own_f = np.concatenate([links.feat_i, links.feat_j])
    other_f = np.concatenate([links.feat_j, links.feat_i])
    quality = np.concatenate([links.quality, links.quality])
    order = np.argsort(owner, kind="stable")
    bounds = np.searchsorted(owner[order], np.arange(n + 1))
    for rb in robots:
        sel = order[bounds[rb.id]:bounds[rb.id + 1]]
        slots = np.searchsorted(rb.nbrs, other[sel])
        rb.table[slots, own_f[sel]] = other_f[sel]
        rb.quality[slots, own_f[sel]] = quality[sel]
        rb.input_table = rb.table.copy()
        rb.input_quality = rb.quality.copy()
    net = Network(n, edges)
    sends = [partial(net.send, i) for i in range(n)]
    changed = []
    for _ in range(iterations):
        for rb in robots:
            rb.send_matches(sends[rb.id])
        net.end_round()
        changed.append(sum(rb.decide(net.inbox(rb.id), sends[rb.id], m) for rb in robots))
        net.end_round()
        for rb in robots:
            rb.apply_decisions(net.inbox(rb.id))
        if changed[-1] == 0:
            break
    cnt = net.counters()
    refined = _links_of(robots)
    stats = {"iterations": len(changed), "fixed_point": changed[-1] == 0,
             "rounds": 2 * len(changed),
             "messages": int(cnt["messages"]), "bytes": int(cnt["bytes"]),
             "changed_per_iteration": changed}
    return refined, stats


def _links_of(robots: list[VoteRobot]) -> Links:
    """The links held at the lower-id end of each edge (reporting only)."""
    ci, fi, cj, fj, q = [], [], [], [], []
    for rb in robots:
        for b, j in enumerate(rb.nbrs.tolist()):
            if j <= rb.id:
                continue
            r = np.flatnonzero(rb.table[b] >= 0)
            ci.append(np.full(r.size, rb.id))
            fi.append(r)
            cj.append(np.full(r.size, j))
            fj.append(rb.table[b, r])
            q.append(rb.quality[b, r])
    if not ci:
        z = np.zeros(0, dtype=np.int64)
        return Links(z, z, z, z, np.zeros(0))
    return Links(np.concatenate(ci), np.concatenate(fi), np.concatenate(cj), np.concatenate(fj),
                 np.concatenate(q))
