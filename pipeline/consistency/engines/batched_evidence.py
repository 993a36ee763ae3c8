"""Batched evaluation of the evidence rule's flood and solve (:mod:`.evidence`) in the simulator.

The per-robot engine (:func:`.evidence.run_evidence_resolution`) steps every robot with a
message and handles its inbox bundle by bundle; every robot of a conflictive set keeps every
bundle of the set and solves the set itself. On a cycle through ``n`` cameras that is about
``n²`` bundles kept and forwarded one by one, and ``n`` solutions of one problem. This module
computes the *same* pass — the same cuts in the same rounds, the same messages and bytes,
the same memory per robot — in two parts.

Flood: one vectorized step per round for all robots
    The bundles one robot floods for one set (a *group*: set ``C``, origin robot ``o``) travel
    together: they leave ``o`` in round 0 in one message to each set neighbour, and a robot
    that receives one for the first time receives all of them in the same message and
    forwards them together (:func:`.evidence.evidence_step`). So the flood is evaluated on
    groups. Each round, every *(group, robot)* pair first received in the last round (the
    frontier; round 0: every group at its origin) is forwarded by that robot to its set
    neighbours but the sender it came from — the robot's own ``set_nbrs`` and the ``src`` of
    the message in its inbox; a receiving robot keeps a group it does not hold yet, taking the
    first copy of its inbox, the one from the lowest-numbered sender (the simulator delivers a
    round's messages by sender, ascending), and that sender becomes the one it will not
    forward to. Whether the receiver already holds the group is read from its own holdings:
    the set's robot graph is symmetric (checked), so breadth-first levels of neighbours differ
    by at most one, and a copy that reaches a robot already holding the group reaches it one
    or two rounds after the robot received it: the frontiers of those two rounds are the
    part of its holdings that can answer yes. Every step reads only the sender's own state (its set neighbours, the group's
    sender), what it sent, and the receiver's own holdings, as the per-robot step does.

    Messages and bytes: a message is one sender-receiver pair in one round, carrying the
    groups forwarded over it; with ``F`` bundles, ``D`` links, ``F_P`` bundles with a
    projection, its size is that of :func:`.evidence._send_bundles`'s payload: ``12 (header)
    + 32 F (set, feat, kp, deg, cam) + 16 D (nbr, w) + 96 F_P (P) + F`` if ``0 < F_P < F``
    (``has_P``). Rounds: the pass ends one round after the last forward, as the per-robot
    loop ends when nothing is in flight.

Solve: once per set, each robot handed its own side in its own round
    A robot solves a set in the round its last group arrives. What it computes,
    :func:`.evidence.solve_set`, is a deterministic function of the set's bundles, and the
    bundles it holds are bit for bit those their robots made (forwarded unchanged, each with
    the projection its robot sent): every robot of the set would compute the same value. The
    simulator computes it once per set, from the bundles as their robots make them
    (:func:`.evidence.own_sets`; the links, cameras and weights of
    :func:`.evidence.set_problem` for all sets at once from the same rows,
    :class:`_SetProblems`, then :func:`.evidence.evidence_cut` set by set), and hands it to
    a robot only when that robot holds the whole set — every other group of the set
    reached it, and the set's groups hold exactly the features of the robot's row ``X_i·``
    (checked) — in the round it does; the robot then cuts its own side (:func:`.evidence.cut_own_side`). This is an evaluation strategy of the
    simulator, not a change of the distributed algorithm: each robot gets exactly the value
    it would compute from what it holds, in the round it would compute it.

Memory: what a robot holds only grows within a pass, so its peak is at its last step, when
it holds every bundle of its sets: :meth:`.evidence.EvidenceState.nbytes` on that holding
(``8`` per set member plus :func:`.evidence.bundle_nbytes` of each bundle) plus
:meth:`~.robot.Robot.memory_bytes`, as the per-robot step measures it. No per-bundle copy is
materialized: the counts follow from the groups' sizes. After the pass each robot's
:class:`~.evidence.EvidenceState` holds its own bundles only (``held_bytes`` is what it would
hold).

Equivalence (tested: ``tests/pipeline/consistency/engines/test_batched.py``): same ``links.csv``,
rounds, messages, bytes and peak memory per robot as the per-robot engine.

Where it applies: the engine's batched evaluation (:func:`.batched.batched_applies`: the
in-process network, no fault, the paper's protocol). A set whose robot graph is not symmetric,
or whose groups do not hold exactly the members a robot lists, is outside what the flood
above evaluates; the pass then runs robot by robot (:func:`.evidence.run_evidence_resolution`).
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.evidence import (
    EvidenceState,
    bundle_nbytes,
    cut_own_side,
    evidence_cut,
    finish_evidence,
    lookups,
    own_set_links,
    own_sets,
    set_geometry,
    set_weights,
)
from pipeline.consistency.evidence import (
    run_evidence_resolution as run_robot_by_robot,
)
from pipeline.consistency.keys import isin_sorted, ranges
from pipeline.consistency.robot import Robot
from pipeline.errors import StageStalledError
from pipeline.transport import HEADER_BYTES, Transport

__all__ = ["run_evidence_resolution", "evidence_pass"]

_EMPTY = np.zeros(0, dtype=np.int64)
#: forwards evaluated in one piece of a round (bounds its arrays; a round is cut between groups)
CHUNK_FORWARDS = 1 << 20


class _SetGraphs:
    """The robot graphs of all conflictive sets, one node per (set, robot), from each robot's
    own ``own_sets``.

    Attributes
    ----------
    N : int — nodes (= groups: node ``v`` is also the group that robot floods for that set)
    robot, F, D, P, members, own_held : (N,) — robot, own bundles, their links, 1 if they
        carry a projection, set members it lists, bytes of its own bundles
    label : (N,) int64 — set label; nodes sorted by (label, robot)
    label_start : (S + 1,) — nodes of set ``k`` are ``label_start[k]:label_start[k+1]``
    indptr, indices : CSR of the directed graph node -> set neighbour nodes (targets
        ascending, i.e. by robot)
    pair : (nnz,) int64 — sender-receiver robot pair of each edge (numbered ``0..n_pairs-1``)
    """

    def __init__(self, n: int, sets: list[dict], projected: list[bool]) -> None:
        lab, rob, F, D, mem, held, nbrs = [], [], [], [], [], [], []
        for i, s in enumerate(sets):
            for label, (members, set_nbrs, bundles) in s.items():
                lab.append(label)
                rob.append(i)
                F.append(len(bundles))
                D.append(sum(bb[1].size for bb in bundles.values()))
                mem.append(members.size)
                held.append(sum(bundle_nbytes(bb) for bb in bundles.values()))
                nbrs.append(set_nbrs)
        order = np.lexsort((np.asarray(rob, dtype=np.int64), np.asarray(lab, dtype=np.int64)))
        self.N = N = order.size
        self.robot = np.asarray(rob, dtype=np.int64)[order]
        self.label = np.asarray(lab, dtype=np.int64)[order]
        self.F = np.asarray(F, dtype=np.int64)[order]
        self.D = np.asarray(D, dtype=np.int64)[order]
        self.members = np.asarray(mem, dtype=np.int64)[order]
        self.own_held = np.asarray(held, dtype=np.int64)[order]
        self.P = np.asarray(projected, dtype=np.int64)[self.robot] if N else _EMPTY
        head = np.r_[True, self.label[1:] != self.label[:-1]] if N else np.zeros(0, bool)
        self.label_start = np.r_[np.flatnonzero(head), N].astype(np.int64)
        lab_idx = np.cumsum(head) - 1
        key = lab_idx * n + self.robot  # ascending
        deg = np.array([len(nbrs[k]) for k in order.tolist()], dtype=np.int64)
        src = np.repeat(np.arange(N, dtype=np.int64), deg)
        dst_robot = np.array([j for k in order.tolist() for j in nbrs[k]], dtype=np.int64)
        want = np.repeat(lab_idx, deg) * n + dst_robot
        pos = np.minimum(np.searchsorted(key, want), max(N - 1, 0))
        self.closed = bool(N == 0 or (key[pos] == want).all())  # every neighbour holds the set
        dst = pos
        self.indptr = np.r_[0, np.cumsum(deg)].astype(np.int64)
        self.indices = dst  # per source, ascending robot within the set: ascending node
        pair_key = self.robot[src] * n + dst_robot
        uniq, self.pair = np.unique(pair_key, return_inverse=True)
        self.n_pairs = int(uniq.size)
        self.pair = self.pair.astype(np.int64).reshape(-1)
        fwd = np.sort(src * max(N, 1) + dst)
        rev = np.sort(dst * max(N, 1) + src)
        self.symmetric = bool(self.closed and np.array_equal(fwd, rev))
        # a robot solves when it holds as many bundles as its row X_i. lists: all groups
        set_F = np.add.reduceat(self.F, self.label_start[:-1]) if N else _EMPTY
        self.set_size = np.diff(self.label_start)
        self.whole = bool(N == 0 or (np.repeat(set_F, self.set_size) == self.members).all())
        self.set_F = set_F

    @property
    def applies(self) -> bool:
        return self.symmetric and self.whole




class _Frontier:
    """The (group, node) pairs first received in the last round, with the node each came
    from, sorted by ``key = group * N + node``; ``prev``: the keys of the round before."""

    def __init__(self, N: int) -> None:
        self.g = np.arange(N, dtype=np.int64)  # round 0: every group at its origin
        self.node = self.g.copy()
        self.parent = np.full(N, -1, dtype=np.int64)
        self.key = self.g * N + self.g
        self.prev = _EMPTY


def _slices(fr: _Frontier, out_degree: np.ndarray, budget: int) -> list[slice]:
    """Runs of the frontier of at most ``budget`` forwards, cut only between groups (the
    receivers of a group must see all its copies of the round at once)."""
    cnt = out_degree[fr.node]
    if int(cnt.sum()) <= budget:
        return [slice(0, fr.g.size)]
    head = np.flatnonzero(np.r_[True, fr.g[1:] != fr.g[:-1]])  # first entry of each group
    upto = np.r_[0, np.cumsum(cnt)][head]  # forwards before each group
    out, start, base = [], 0, 0
    for h, u in zip(head[1:].tolist(), upto[1:].tolist(), strict=True):
        if u - base > budget and h > start:
            out.append(slice(start, h))
            start, base = h, u
    out.append(slice(start, fr.g.size))
    return out


def _forward(sg: _SetGraphs, fr: _Frontier, part: slice) -> tuple:
    """Part ``part`` of a round: its frontier entries forward, the receivers keep the groups
    new to them. Returns the part's messages ``(pair, F, D, F_P)`` (one entry per
    sender-receiver pair) and its next frontier ``key``, ``parent``."""
    N = sg.N
    g, node, parent = fr.g[part], fr.node[part], fr.parent[part]
    start, stop = sg.indptr[node], sg.indptr[node + 1]
    pos = ranges(start, stop)
    cnt = stop - start
    tj = sg.indices[pos]
    keep = tj != np.repeat(parent, cnt)  # not back to the sender it came from
    pos, tj = pos[keep], tj[keep]
    tg = np.repeat(g, cnt)[keep]
    tk = np.repeat(node, cnt)[keep]
    # the round's messages: the groups forwarded over each sender-receiver pair
    pair, inv = np.unique(sg.pair[pos], return_inverse=True)
    inv = inv.reshape(-1)
    msgs = (pair, np.bincount(inv, sg.F[tg], pair.size), np.bincount(inv, sg.D[tg], pair.size),
            np.bincount(inv, sg.F[tg] * sg.P[tg], pair.size))
    # receivers keep what they do not hold: the first copy, from the lowest sender
    key = tg * N + tj
    new = ~(isin_sorted(key, fr.key) | isin_sorted(key, fr.prev))
    key, tk = key[new], tk[new]
    order = np.lexsort((tk, key))  # the nodes of a set ascend with their robot
    key, tk = key[order], tk[order]
    first = np.r_[True, key[1:] != key[:-1]] if key.size else np.zeros(0, dtype=bool)
    return msgs, key[first], tk[first]


def _message_bytes(F: np.ndarray, D: np.ndarray, FP: np.ndarray) -> int:
    """Bytes of bundle messages with ``F`` bundles, ``D`` links, ``FP`` projections each."""
    mixed = (FP > 0) & (FP < F)
    return int((HEADER_BYTES + 32 * F + 16 * D + 96 * FP + np.where(mixed, F, 0)).sum())


def _flood(sg: _SetGraphs, cap: int) -> tuple[int, int, int, np.ndarray, np.ndarray]:
    """Evaluate the flood; returns rounds, messages, bytes, each node's solve round (its last
    arrival) and the groups it received, ``(N,)`` each."""
    N = sg.N
    solve_round = np.full(N, -1, dtype=np.int64)
    received = np.zeros(N, dtype=np.int64)
    out_degree = np.diff(sg.indptr)
    fr = _Frontier(N)
    t, messages, nbytes = 0, 0, 0
    while fr.g.size:
        parts = [_forward(sg, fr, part) for part in _slices(fr, out_degree, CHUNK_FORWARDS)]
        key = np.concatenate([p[1] for p in parts])  # the parts follow the groups: sorted
        fr.prev, fr.key = fr.key, key
        fr.g, fr.node, fr.parent = key // N, key % N, np.concatenate([p[2] for p in parts])
        msgs = [p[0] for p in parts if p[0][0].size]
        if not msgs:
            break
        if len(msgs) == 1:
            pair, F, D, FP = msgs[0]
        else:  # a pair's message carries the groups of every part
            pair, inv = np.unique(np.concatenate([m[0] for m in msgs]), return_inverse=True)
            F, D, FP = (np.bincount(inv.reshape(-1), np.concatenate([m[c] for m in msgs]),
                                    pair.size) for c in (1, 2, 3))
        F, D, FP = (x.astype(np.int64) for x in (F, D, FP))
        messages += int(pair.size)
        nbytes += _message_bytes(F, D, FP)
        t += 1  # delivered in round t; the groups kept are forwarded in it
        solve_round[fr.node] = t  # levels only grow: a node's last arrival wins
        np.add.at(received, fr.node, 1)
        if t > cap:
            raise StageStalledError(f"evidence resolution did not end within {cap} rounds")
    return t, messages, nbytes, solve_round, received


class _SetProblems:
    """:func:`.evidence.set_problem` of every set at once, from the robots' own set links
    (:func:`.evidence.own_set_links`): the same links, order, cameras and weights.

    Each set's links once, ordered by ``(lo, hi)`` (their ends' global ids), with the weight
    of the first bundle entry in the set's bundle order (ascending gid) and the triangle
    support (:func:`.evidence.set_weights`: third cameras of the common neighbours of the
    two ends, among the set's links). The sets are disjoint, so the common neighbours are
    found on all their links together. A set with known poses counts only the triangles
    that pass the three-view test, set by set (:meth:`weight`).

    Attributes
    ----------
    label : (S,) int64 — set labels, ascending; set ``k``'s links are ``start[k]:start[k+1]``
    a, b, cam_a, cam_b : (E,) — as :func:`.evidence.set_problem` returns them
    local : (E,) float64 — the links' local weights (what their bundles carry)
    w : (E,) float64 — ``local`` plus the triangle support of every common feature (the
        weight of a set without poses)
    """

    def __init__(self, robots: list[Robot], links: list[tuple]) -> None:
        lab = np.concatenate([x[0] for x in links] + [_EMPTY])
        ga = np.concatenate([rb.gid0 + x[1] for rb, x in zip(robots, links, strict=True)]
                            + [_EMPTY]).astype(np.int64)
        gb = np.concatenate([x[3] for x in links] + [_EMPTY]).astype(np.int64)
        w = np.concatenate([x[4] for x in links] + [np.zeros(0)]).astype(np.float64)
        # bundle order within a set: ascending gid (robots ascend, gids are theirs), a
        # bundle's links in table order: entries of each robot come so, a stable sort by set
        # keeps it
        lo, hi = np.minimum(ga, gb), np.maximum(ga, gb)
        order = np.lexsort((np.arange(lab.size), hi, lo, lab))
        lab, lo, hi = lab[order], lo[order], hi[order]
        first = np.r_[True, (lab[1:] != lab[:-1]) | (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])] \
            if lab.size else np.zeros(0, dtype=bool)
        self.a, self.b, w = lo[first], hi[first], w[order[first]]
        lab = lab[first]
        head = np.flatnonzero(np.r_[True, lab[1:] != lab[:-1]]) if lab.size else _EMPTY
        self.label = lab[head]
        self.start = np.r_[head, lab.size].astype(np.int64)
        offsets = robots[0].offsets if robots else np.zeros(1, dtype=np.int64)
        self.cam_a = np.searchsorted(offsets, self.a, side="right") - 1
        self.cam_b = np.searchsorted(offsets, self.b, side="right") - 1
        self.local = w
        self.w = set_weights(self.a, self.b, self.cam_a, self.cam_b, w)

    def of(self, label: int) -> slice:
        k = int(np.searchsorted(self.label, label))
        return slice(int(self.start[k]), int(self.start[k + 1]))

    def weight(self, e: slice, keypoints: dict | None, projections: dict | None) -> np.ndarray:
        """The weights of set ``e`` (:meth:`of`) as :func:`.evidence.set_problem` gives them
        with the set's geometry (:func:`.evidence.set_geometry`; ``None``: ``w[e]``)."""
        if keypoints is None or projections is None:
            return self.w[e]
        return set_weights(self.a[e], self.b[e], self.cam_a[e], self.cam_b[e], self.local[e],
                           *lookups(keypoints, projections))


def run_evidence_resolution(robots: list[Robot], network: Transport,
                            max_rounds: int | None = None, on_round=None) -> dict:
    """One flood-and-solve pass of the evidence rule on all robots, evaluated in batch;
    returns what :func:`.evidence.run_evidence_resolution` returns.

    Parameters
    ----------
    robots : list[Robot], (n,) — equipped with their evidence (:func:`.evidence.equip`)
    network : Transport — the in-process network (clock advanced, traffic counted)
    max_rounds : int or None — cap of the pass (default ``n + 2``, as robot by robot)
    on_round : callable ``(round) -> None`` or None — progress report

    Returns
    -------
    dict — ``rounds``, ``conflictive_sets``, ``robots_in_sets``

    Notes
    -----
    Time and memory grow with the bundle transfers of the flood grouped by (set, origin):
    ``O(Σ_C |C_robots| · |C_links| log)`` numpy work in ``diam(C) + 1`` vectorized rounds,
    arrays of a round bounded by :data:`CHUNK_FORWARDS` forwards, plus one solution per set.
    """
    n = len(robots)
    links = [own_set_links(rb) for rb in robots]
    sets = [own_sets(rb, x) for rb, x in zip(robots, links, strict=True)]
    projected = [rb.evidence.projection is not None for rb in robots]
    sg = _SetGraphs(n, sets, projected)
    if not sg.applies:
        return run_robot_by_robot(robots, network, max_rounds=max_rounds, on_round=on_round)
    cap = max_rounds if max_rounds is not None else n + 2
    rounds, messages, nbytes, solve_round, received = _flood(sg, cap)
    if messages:
        network.count("bundle", messages, nbytes)
    for t in range(1, rounds + 1):
        network.end_round()
        if on_round is not None:
            on_round(t)
    # a robot holds a set when every other group of it arrived
    complete = received == np.repeat(sg.set_size, sg.set_size) - 1
    held_set = 8 * sg.members + np.repeat(np.add.reduceat(sg.own_held, sg.label_start[:-1])
                                          if sg.N else _EMPTY, sg.set_size)
    held = np.where(complete, held_set, 8 * sg.members + sg.own_held)
    held_by_robot = np.bincount(sg.robot, weights=held, minlength=n).astype(np.int64)
    for rb, s in zip(robots, sets, strict=True):
        st: EvidenceState = rb.evidence
        st.bundles = {lab: dict(v[2]) for lab, v in s.items()}
        st.set_members = {lab: v[0] for lab, v in s.items()}
        st.set_nbrs = {lab: v[1] for lab, v in s.items()}
        st.solved = set()
        st.held_bytes = int(held_by_robot[rb.id])
        rb.measure_memory()
        rb.peak_memory_bytes = max(rb.peak_memory_bytes, rb.memory_bytes() + st.nbytes())
    # one solution per set, each robot's side cut in its own solve round (a robot's sets at
    # once: each link lies in one set, so the order of the sets does not matter)
    handed: dict[int, list] = {}
    pb = _SetProblems(robots, links)
    for k in range(sg.label_start.size - 1):
        a, b = sg.label_start[k], sg.label_start[k + 1]
        nodes = np.arange(a, b)[complete[a:b]]
        if nodes.size == 0:
            continue
        label = int(sg.label[a])
        kp = P = None
        if all(projected[i] for i in sg.robot[a:b].tolist()):
            bundles: dict = {}
            for i in sg.robot[a:b].tolist():
                bundles.update(sets[i][label][2])
            kp, P = set_geometry(bundles)
        e = pb.of(label)
        sol = (pb.a[e], pb.b[e], pb.cam_a[e], pb.cam_b[e])
        solution = (*sol, evidence_cut(*sol, pb.weight(e, kp, P), kp, P))
        for v in nodes.tolist():
            i = int(sg.robot[v])
            robots[i].evidence.solved.add(label)
            handed.setdefault(i, []).append((solution, int(solve_round[v])))
    for i, got in handed.items():
        parts = list(zip(*(sol for sol, _ in got), strict=True))
        when = np.concatenate([np.full(sol[0].size, t, dtype=np.int64) for sol, t in got])
        cut_own_side(robots[i], tuple(np.concatenate(p) for p in parts), when)
    unsolved = sorted(set(sg.robot[~complete].tolist()))
    return finish_evidence(robots, rounds, unsolved, int(sg.label_start.size - 1),
                           sum(1 for s in sets if s))


def evidence_pass(robots: list[Robot], network: Transport, protocol=None, iteration: int = 0,
                  on_round=None) -> dict:
    """The ``evidence`` rule's batched engine (:mod:`pipeline.consistency.rules`):
    :func:`run_evidence_resolution`; the rule needs no protocol object or iteration number."""
    return run_evidence_resolution(robots, network, on_round=on_round)
