"""Decentralized resolution of inconsistent associations (Aragüés et al., Sec. IV, Alg. 1).

The root of each conflictive set (eq. 10, found by :mod:`.detection`) opens one component per
of its features in the set and sends *component requests* along their links (Alg. 1 lines
2–5). A robot receiving a request for component ``C_q`` from ``f_s^j`` to ``f_r^i`` applies
(lines 8–16):

(a) ``f_r^i`` already in ``C_q``: nothing;
(b) ``f_r^i`` in another component: delete ``[W_ij]_{r,s}``, reply *reject*;
(c) another ``f_{r'}^i`` already in ``C_q``: delete ``[W_ij]_{r,s}``, reply *reject*;
(d) otherwise: assign ``f_r^i`` to ``C_q`` and send requests along its links.

On a reject the sender deletes its side ``[W_ji]_{s,r}`` (lines 17–19).

Stated choices:

* Component id ``q`` = global id ``offsets[root] + r`` of the root feature: unique without
  coordination (a feature belongs to one robot and opens at most one component).
* Concurrent requests delivered in one round are handled in the order
  ``(component id, sender robot, sender feature)``; the requests of a round are classified
  against the state *before* the round, then the remaining contention (two components
  asking for one feature, or one component asking for two features of this robot) is
  settled in that order — the result is exactly that of handling them one by one.
* A feature that joins ``C_q`` (case d) sends requests along its remaining links, except the
  links over which a request arrived this round (those are already settled: same component
  at both ends, or deleted).
* Rounds: the roots' requests are sent in round 0 and delivered in round 1; a feature at
  depth ``h`` of its component joins in round ``h ≤ n − 1`` (Thm. 4.3 (i)); the last
  receiver deletions happen by round ``n`` and the rejects they send arrive by round
  ``n + 1``.

Payloads (int32 index lists): a ``request`` carries ``q``, the sender's features and the
receiver's features; a ``reject`` carries the rejecting robot's features and the receiver's.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.consistency.robot import CASE_B, CASE_C, ON_REJECT, Robot
from pipeline.transport import Message

__all__ = ["start_resolution", "resolution_step", "finish_resolution", "classify_requests",
           "settle_contention", "OUTCOME_A", "OUTCOME_B", "OUTCOME_C", "OUTCOME_D"]

Send = Callable[[int, str, dict], None]

# outcomes of a request at its receiver: Alg. 1 lines 8-16, cases (a)-(d)
OUTCOME_A, OUTCOME_B, OUTCOME_C, OUTCOME_D = 0, 1, 2, 3


def start_resolution(robot: Robot, send: Send) -> int:
    """Alg. 1 lines 2–5: open a component per own feature of each set this robot is root of.

    Returns
    -------
    int — number of conflictive sets this robot is root of
    """
    if not robot.root_of_set:
        return 0
    my_sets = np.array([lab for lab, root in robot.root_of_set.items() if root == robot.id],
                       dtype=np.int64)
    if my_sets.size == 0:
        return 0
    mine = robot.conflictive & np.isin(robot.set_label, my_sets)
    rows = np.flatnonzero(mine)
    robot.component[rows] = robot.gid0 + rows  # line 4: one component per feature
    robot.assigned_round[rows] = 0
    _send_requests(robot, mine, None, send)  # line 5
    return int(my_sets.size)


def _send_requests(robot: Robot, new: np.ndarray, settled: np.ndarray | None, send: Send) -> None:
    """Component requests from the features in ``new`` (m_i,) along their alive links."""
    sel = robot.link_alive & new[robot.link_r]
    if settled is not None:
        sel &= ~settled
    idx = np.flatnonzero(sel)
    if idx.size == 0:
        return
    idt = np.int32 if robot.m_total < 2**31 else np.int64
    cut = np.flatnonzero(np.diff(robot.link_nbr[idx])) + 1
    for part in np.split(idx, cut):
        r = robot.link_r[part]
        send(int(robot.link_nbr[part[0]]), "request",
             {"q": robot.component[r].astype(idt), "src_feat": r.astype(np.int32),
              "dst_feat": robot.link_s[part].astype(np.int32)})


def _send_rejects(robot: Robot, links: np.ndarray, send: Send) -> None:
    if links.size == 0:
        return
    links = np.sort(links)  # table order groups by neighbour
    cut = np.flatnonzero(np.diff(robot.link_nbr[links])) + 1
    for part in np.split(links, cut):
        send(int(robot.link_nbr[part[0]]), "reject",
             {"src_feat": robot.link_r[part].astype(np.int32),
              "dst_feat": robot.link_s[part].astype(np.int32)})


def classify_requests(cur: np.ndarray, q: np.ndarray, held: np.ndarray):
    """Alg. 1 lines 8–12 for received requests: the cases that need no ordering.

    Parameters
    ----------
    cur : (k,) int — the component of each request's target feature (``-1``: unassigned)
    q : (k,) int — the component each request offers
    held : (k,) bool — the receiver already holds component ``q`` on another feature

    Returns
    -------
    outcome : (k,) int8 — ``OUTCOME_A`` (already in ``q``), ``OUTCOME_B`` (in another component), ``OUTCOME_C``
        (target free, ``q`` held), ``-1`` for the candidates
    cand : (k',) int — indices of the candidates (target free, ``q`` not held), settled by
        :func:`settle_contention`
    """
    outcome = np.full(q.size, -1, dtype=np.int8)
    outcome[cur == q] = OUTCOME_A                        # (a)
    outcome[(cur >= 0) & (cur != q)] = OUTCOME_B         # (b)
    outcome[(cur < 0) & held] = OUTCOME_C                # (c)
    return outcome, np.flatnonzero((cur < 0) & ~held)


def settle_contention(q: np.ndarray, r: np.ndarray, outcome: np.ndarray, cand: np.ndarray) -> None:
    """Cases for the candidate requests (target unassigned, ``q`` not held), in order.

    ``cand`` indexes the requests already sorted by (component, sender robot, sender feature).
    The first candidate for a free feature and a free component wins (d); later ones for the
    same feature are (a) if same component else (b); for the same component, (c).
    """
    qc, rc = q[cand], r[cand]
    if np.unique(qc).size == qc.size and np.unique(rc).size == rc.size:
        outcome[cand] = OUTCOME_D
        return
    taken_r: dict[int, int] = {}
    taken_q: set[int] = set()
    # only requests that compete for a feature or a component reach this loop
    for k, qq, rr in zip(cand.tolist(), qc.tolist(), rc.tolist(), strict=True):
        if rr in taken_r:
            outcome[k] = OUTCOME_A if taken_r[rr] == qq else OUTCOME_B
        elif qq in taken_q:
            outcome[k] = OUTCOME_C
        else:
            outcome[k] = OUTCOME_D
            taken_r[rr] = qq
            taken_q.add(qq)


def resolution_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """One round of Alg. 1 (lines 8–19) for one robot."""
    reqs = [m for m in inbox if m.kind == "request"]
    if reqs:
        q = np.concatenate([m.payload["q"] for m in reqs]).astype(np.int64)
        j = np.concatenate([np.full(m.payload["q"].shape[0], m.src, dtype=np.int64) for m in reqs])
        s = np.concatenate([m.payload["src_feat"] for m in reqs]).astype(np.int64)
        r = np.concatenate([m.payload["dst_feat"] for m in reqs]).astype(np.int64)
        order = np.lexsort((s, j, q))  # stated order: (component, sender robot, sender feature)
        q, j, s, r = q[order], j[order], s[order], r[order]
        link = robot.find_links(j, s)
        valid = link >= 0
        valid[valid] = robot.link_alive[link[valid]] & (robot.link_r[link[valid]] == r[valid])
        # a request over a link this robot no longer holds (only possible under faults):
        # reject it so that the sender drops its side too
        stale = link[~valid & (link >= 0)]
        q, j, s, r, link = q[valid], j[valid], s[valid], r[valid], link[valid]

        cur = robot.component[r]
        held = np.isin(q, robot.component[robot.component >= 0])
        outcome, cand = classify_requests(cur, q, held)
        if cand.size:
            settle_contention(q, r, outcome, cand)

        cut_b = link[outcome == OUTCOME_B]
        cut_c = link[outcome == OUTCOME_C]
        robot.delete_links(cut_b, round_, CASE_B)     # line 10
        robot.delete_links(cut_c, round_, CASE_C)
        _send_rejects(robot, np.concatenate([cut_b, cut_c, stale]),
                      send)                           # line 11

        joined = outcome == OUTCOME_D
        new = np.zeros(robot.m, dtype=bool)
        if joined.any():
            robot.component[r[joined]] = q[joined]    # line 13
            robot.assigned_round[r[joined]] = round_
            new[r[joined]] = True
            settled = np.zeros(robot.link_r.size, dtype=bool)
            settled[link] = True
            _send_requests(robot, new, settled, send)  # line 14

    for m in inbox:                                   # lines 17–19
        if m.kind != "reject":
            continue
        link = robot.find_links(np.full(m.payload["src_feat"].shape[0], m.src), m.payload["src_feat"])
        ok = link >= 0
        ok[ok] = robot.link_r[link[ok]] == m.payload["dst_feat"][ok]
        robot.delete_links(link[ok], round_, ON_REJECT)
    robot.measure_memory()


def finish_resolution(robot: Robot) -> None:
    """End of a resolution: the next detection re-examines the unassigned conflictive features.

    Sec. IV, after Cor. 4.4: "the detection algorithm can be executed on the subgraph defined
    by this smaller subset of features" — those conflictive and left without a component.
    """
    robot.candidates = robot.conflictive & (robot.component < 0)
