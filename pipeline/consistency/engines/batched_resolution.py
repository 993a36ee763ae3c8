"""Batched evaluation of Alg. 1 (Aragüés et al., Sec. IV) in the in-process simulator.

The per-robot engine steps each robot with a message through
:func:`~.resolution.resolution_step`. On the simulator's lossless static network with the
paper's protocol (:func:`.batched.batched_applies`) this module computes the *same* rounds
of all robots at once, on their link tables stacked (robot 0's table, then robot 1's, ...).

Why it obeys the one rule (docs/DESIGN.md: a robot sees only its own state and its inbox)
    A request or reject in flight is an entry ``(link e at the receiver, q)``: ``e`` is the
    receiver's own row of its table for the link the message names (the per-robot receiver
    finds it with :meth:`~.robot.Robot.find_links` from the sender's feature ``s`` and its
    own ``r``, both in the payload), ``q`` the component the payload carries. Every update
    of a round reads, for receiver ``i``, only ``i``'s own features (``component``), ``i``'s
    own links and the entries addressed to ``i``: the cases (a)–(d) of lines 8–16 are
    classified against ``i``'s components before the round, contention is settled in the
    order ``(q, sender robot, sender feature)`` within ``i``'s requests
    (:func:`~.resolution.settle_contention`), the new requests go along ``i``'s alive links
    not settled this round (line 14), and rejects delete ``i``'s side (lines 17–19) after
    its requests are handled, as one step of :func:`~.resolution.resolution_step` does. No
    update mixes two receivers, so stacking them changes nothing.

Equivalence (tested: ``tests/pipeline/consistency/engines/test_batched.py``)
    Same components, assignment rounds, link deletions (round, case, iteration), rounds,
    messages and bytes (each message a robot would send, one per (sender, neighbour) and
    kind, counted with :meth:`~pipeline.transport.Transport.count` at the size
    :attr:`~pipeline.transport.Message.nbytes` gives its payload) and peak memory
    (:meth:`~.robot.Robot.measure_memory` of every robot that received a message; a
    resolution changes none of the arrays it counts).

Round 0 is each robot's own :func:`~.resolution.start_resolution` (lines 2–5), its requests
taken as entries instead of messages. A link table that is not the mirror of its
neighbours' (never on the fault-free simulator) makes :func:`run_resolution` step the robots
one by one instead.
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.engines.phases import run_phase
from pipeline.consistency.keys import isin_sorted
from pipeline.consistency.protocols import RESOLUTION, PaperProtocol, end_phase
from pipeline.consistency.resolution import (
    OUTCOME_B,
    OUTCOME_C,
    OUTCOME_D,
    classify_requests,
    settle_contention,
    start_resolution,
)
from pipeline.consistency.robot import CASE_B, CASE_C, ON_REJECT, Robot
from pipeline.errors import StageStalledError
from pipeline.transport import HEADER_BYTES, Transport

__all__ = ["run_resolution"]

_EMPTY = np.zeros(0, dtype=np.int64)


class _Tables:
    """Every robot's link table and features, stacked (global ids).

    Attributes
    ----------
    owner, nbr, r, s : (E,) int64 — link ``e`` of robot ``owner``: its feature ``r`` to
        feature ``s`` of ``nbr`` (each robot's table in its own ``(nbr, s)`` order)
    g : (E,) int64 — global id ``offsets[owner] + r`` of the owner's feature
    mate : (E,) int64 — the same link in the neighbour's table
    alive, del_round, del_case, del_iter : (E,) — the robots' link state and log
    comp, assigned : (m_total,) — ``component`` and ``assigned_round`` of every feature
    f_owner : (m_total,) int64 — robot of each feature
    """

    def __init__(self, robots: list[Robot]) -> None:
        n = len(robots)
        self.bounds = np.concatenate([[0], np.cumsum([rb.link_r.size for rb in robots])])
        sizes = np.diff(self.bounds)
        self.owner = np.repeat(np.arange(n, dtype=np.int64), sizes)
        self.nbr = np.concatenate([rb.link_nbr for rb in robots] + [_EMPTY]).astype(np.int64)
        self.r = np.concatenate([rb.link_r for rb in robots] + [_EMPTY]).astype(np.int64)
        self.s = np.concatenate([rb.link_s for rb in robots] + [_EMPTY]).astype(np.int64)
        offsets = robots[0].offsets if robots else np.zeros(1, dtype=np.int64)
        self.offsets = offsets
        self.g = offsets[self.owner] + self.r
        self.alive = np.concatenate([rb.link_alive for rb in robots] + [np.zeros(0, bool)])
        self.del_round = np.concatenate([rb.deleted_round for rb in robots]
                                        + [np.zeros(0, np.int32)])
        self.del_case = np.concatenate([rb.deleted_case for rb in robots] + [np.zeros(0, np.int8)])
        self.del_iter = np.concatenate([rb.deleted_iteration for rb in robots]
                                       + [np.zeros(0, np.int32)])
        self.iteration = np.repeat(np.array([rb.iteration for rb in robots], dtype=np.int32),
                                   sizes)
        self.comp = np.concatenate([rb.component for rb in robots] + [_EMPTY])
        self.assigned = np.concatenate([rb.assigned_round for rb in robots]
                                       + [np.zeros(0, np.int32)])
        fpc = np.diff(offsets)
        self.f_owner = np.repeat(np.arange(n, dtype=np.int64), fpc)
        self.m_total = int(offsets[-1])
        # the mirror of each link: (nbr, owner, s, r) is a row of nbr's table when every link
        # is held at both ends (build_robots); each table is sorted by (nbr, s)
        E = self.owner.size
        span = int(fpc.max(initial=0)) + 1
        if E and n * n * span < 2**62:  # one int64 key: the stacked tables are sorted by it
            key = (self.owner * n + self.nbr) * span + self.s
            back = (self.nbr * n + self.owner) * span + self.r
            # mirrored iff the mirrors' keys, sorted, are the (strictly increasing) keys; then
            # the sort names each link's mirror (one sort: cheaper than a search per link)
            order = np.argsort(back)
            self.mirrored = bool(np.array_equal(back[order], key) and np.all(key[1:] > key[:-1]))
            if self.mirrored:
                self.mate = np.empty(E, dtype=np.int64)
                self.mate[order] = np.arange(E)
            else:
                self.mate = np.minimum(np.searchsorted(key, back), E - 1)
        else:
            order = np.lexsort((self.r, self.owner, self.nbr))
            self.mirrored = bool(np.array_equal(self.nbr[order], self.owner)
                                 and np.array_equal(self.owner[order], self.nbr)
                                 and np.array_equal(self.r[order], self.s)
                                 and np.array_equal(self.s[order], self.r))
            self.mate = np.empty(E, dtype=np.int64)
            self.mate[order] = np.arange(E)

    def write_back(self, robots: list[Robot]) -> None:
        """Hand every robot its own rows of the state."""
        for rb in robots:
            a, b = self.bounds[rb.id], self.bounds[rb.id + 1]
            fa, fb = self.offsets[rb.id], self.offsets[rb.id + 1]
            rb.link_alive[:] = self.alive[a:b]
            rb.deleted_round[:] = self.del_round[a:b]
            rb.deleted_case[:] = self.del_case[a:b]
            rb.deleted_iteration[:] = self.del_iter[a:b]
            rb.component[:] = self.comp[fa:fb]
            rb.assigned_round[:] = self.assigned[fa:fb]

    def delete(self, links: np.ndarray, round_: int, case: int) -> None:
        """:meth:`~.robot.Robot.delete_links` on each owner's rows."""
        fresh = links[self.alive[links]]
        self.alive[fresh] = False
        self.del_round[fresh] = round_
        self.del_case[fresh] = case
        self.del_iter[fresh] = self.iteration[fresh]


def _count(network: Transport, kind: str, src: np.ndarray, dst: np.ndarray, n: int,
           entry_bytes: int) -> None:
    """Count one message per (sender, neighbour) with entries: header + ``entry_bytes`` each."""
    if src.size == 0:
        return
    msgs = np.unique(src * max(n, 1) + dst).size
    network.count(kind, msgs, msgs * HEADER_BYTES + entry_bytes * src.size)


def _requests_from(tab: _Tables, new: np.ndarray, settled: np.ndarray | None):
    """Requests of Alg. 1 lines 5 and 14: along the alive links of the features ``new``
    (m_total,) bool, except the links ``settled`` this round; entries ``(sender link, q)``."""
    sel = tab.alive & new[tab.g]
    if settled is not None:
        sel &= ~settled
    links = np.flatnonzero(sel)
    return links, tab.comp[tab.g[links]]


def run_resolution(robots: list[Robot], network: Transport, protocol: PaperProtocol,
                   iteration: int, max_rounds: int | None = None, on_round=None) -> dict:
    """Alg. 1 of all robots, evaluated in batch; returns what :func:`.phases.run_phase`
    returns for it (``rounds``, ``start_round``, ``lost``, ``conflictive_sets``)."""
    tab = _Tables(robots)
    if not tab.mirrored:
        return _run_stepped(robots, network, protocol, iteration, max_rounds, on_round)
    n = len(robots)
    start_round = int(network.round)
    idx_size = np.dtype(np.int32 if tab.m_total < 2**31 else np.int64).itemsize
    req_bytes = idx_size + 8  # q, src_feat int32, dst_feat int32
    rej_bytes = 8  # src_feat int32, dst_feat int32

    # round 0 (lines 2-5): each robot opens its components; its requests become entries
    before = tab.comp.copy()
    rooted = 0
    for rb in robots:
        rooted += start_resolution(rb, _drop)
        network.note_memory(rb.id, rb.peak_memory_bytes)
    tab.comp = np.concatenate([rb.component for rb in robots] + [_EMPTY])
    tab.assigned = np.concatenate([rb.assigned_round for rb in robots] + [np.zeros(0, np.int32)])
    roots = (tab.comp >= 0) & (before < 0)  # the features opened in round 0
    req_link, req_q = _requests_from(tab, roots, None)
    _count(network, "request", tab.owner[req_link], tab.nbr[req_link], n, req_bytes)
    rej_link = _EMPTY
    stepped = np.zeros(n, dtype=bool)
    cap = protocol.max_rounds(RESOLUTION, robots) if max_rounds is None else max_rounds
    t = 0
    while req_link.size or rej_link.size:
        network.end_round()
        t += 1
        if on_round is not None:
            on_round(t)
        stepped[tab.nbr[req_link]] = True
        stepped[tab.nbr[rej_link]] = True
        req_link, req_q, rej_link = _round(tab, req_link, req_q, rej_link, t, network, n,
                                           req_bytes, rej_bytes)
        if t > cap:
            raise StageStalledError(f"resolution did not end within {cap} rounds")
    tab.write_back(robots)
    for rb in robots:
        if stepped[rb.id]:
            rb.measure_memory()
            network.note_memory(rb.id, rb.peak_memory_bytes)
    end_phase(RESOLUTION, robots)
    return dict(rounds=t, start_round=start_round, lost=False, conflictive_sets=int(rooted))


def _drop(dst: int, kind: str, payload: dict) -> None:
    """Round 0's sends: the batched loop takes the requests from the robots' state."""


def _round(tab: _Tables, req_link: np.ndarray, req_q: np.ndarray, rej_link: np.ndarray,
           t: int, network: Transport, n: int, req_bytes: int, rej_bytes: int):
    """Round ``t`` of every receiver (lines 8-19).

    ``req_link`` / ``rej_link``: the sender's link of each request / reject delivered now.
    Returns the requests sent (sender links, components) and the rejects sent (links)."""
    # at the receiver: its own link of each request (find_links on (sender, s), r checked)
    e = tab.mate[req_link]
    q = req_q
    i, j, s = tab.owner[e], tab.nbr[e], tab.s[e]
    order = np.lexsort((s, j, q, i))  # per receiver: (component, sender robot, sender feature)
    e, q, i = e[order], q[order], i[order]
    valid = tab.alive[e]
    stale = e[~valid]  # only under faults: rejected so that the sender drops its side
    e, q, i = e[valid], q[valid], i[valid]
    g = tab.g[e]
    cur = tab.comp[g]
    has = tab.comp >= 0
    held_keys = np.unique(tab.f_owner[has] * tab.m_total + tab.comp[has])
    key_q = i * tab.m_total + q
    outcome, cand = classify_requests(cur, q, isin_sorted(key_q, held_keys))
    if cand.size:
        # (d) unless two candidates of one receiver share a feature or a component: those
        # settle in order (each receiver's requests are contiguous and in its order)
        dup = _duplicated(g[cand]) | _duplicated(key_q[cand])
        outcome[cand[~dup]] = OUTCOME_D
        if dup.any():
            settle_contention(key_q, g, outcome, cand[dup])
    cut_b, cut_c = e[outcome == OUTCOME_B], e[outcome == OUTCOME_C]
    tab.delete(cut_b, t, CASE_B)                  # line 10
    tab.delete(cut_c, t, CASE_C)
    rejects = np.concatenate([cut_b, cut_c, stale])  # line 11
    _count(network, "reject", tab.owner[rejects], tab.nbr[rejects], n, rej_bytes)
    joined = outcome == OUTCOME_D
    new = np.zeros(tab.m_total, dtype=bool)
    sent_link, sent_q = _EMPTY, _EMPTY
    if joined.any():
        tab.comp[g[joined]] = q[joined]           # line 13
        tab.assigned[g[joined]] = t
        new[g[joined]] = True
        settled = np.zeros(tab.owner.size, dtype=bool)
        settled[e] = True
        sent_link, sent_q = _requests_from(tab, new, settled)  # line 14
        _count(network, "request", tab.owner[sent_link], tab.nbr[sent_link], n, req_bytes)
    tab.delete(tab.mate[rej_link], t, ON_REJECT)  # lines 17-19
    return sent_link, sent_q, rejects


def _duplicated(a: np.ndarray) -> np.ndarray:
    """True where a value of ``a`` occurs more than once."""
    _, inv, counts = np.unique(a, return_inverse=True, return_counts=True)
    return counts[inv] > 1


def _run_stepped(robots, network, protocol, iteration, max_rounds, on_round) -> dict:
    """The fallback: the engine's one loop, robot by robot (:func:`.phases.run_phase`)."""
    return run_phase(robots, network, protocol, RESOLUTION, iteration, max_rounds, on_round)
