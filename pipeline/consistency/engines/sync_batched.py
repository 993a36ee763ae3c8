"""Batched evaluation of the ``sync`` rule (:mod:`..sync`) in the in-process simulator.

The per-robot driver (:func:`run_sync`) steps every robot with a message in every
round, robot by robot. That is the code the robots run one at a time over a reliable
channel or as their own programs. On the simulator's lossless static network this module
computes the *same* rounds for all robots at once, with numpy over the robots' link tables
stacked (one row per link end, a *half-link*: robot ``i``, its own feature ``f``, the far
feature ``g`` on neighbour ``j``), and gives every robot the state, and the network the
messages and bytes, that robot-by-robot stepping gives.

Why each robot's update still reads only its own state and its inbox (docs/DESIGN.md)
    Every quantity below is the value a robot computes from its own rows and from what its
    inbox holds in that round (:mod:`..sync`, "What each end knows"): at the start of each
    phase A both ends of an open or inside link hold the clusters' current labels and camera
    sets, so one array ``label`` of every feature's cluster (each robot's own ``label``
    rows, stacked) and one camera bit set per cluster serve both ends; where a robot's
    record differs from the current cluster (a link closed as ineligible keeps the far label
    of its closing round), the record is kept per half-link (``frozen``). Decisions are the
    robots' own: a link closes when its own two clusters share a camera; a feature's best
    is the largest key of its own open links, then the largest heard; a merge needs the link
    to be the best held at both ends.

Steps (one vectorized step per network round; the phases of :mod:`..sync`)
    Support (1 round). Robot ``i``'s message to ``j`` lists, for each of the ``F`` own
    features linked to ``j``, its ``deg`` far ends: ``12 + 8 F + id · Σ deg`` bytes. ``τ`` of a
    link is what the robot counts from the list: the far ends of the far feature that are
    linked to its own feature (chunks of :data:`CHUNK` entries). Both ends hold the same
    ``w``; its order ``(w, -t, -lo, -hi)`` (``t`` = :func:`..keys.tie_key`) becomes one
    integer ``rank`` per link.

    Phase A (best). Closing: open links inside a cluster; open links whose clusters merged in
    the last phase B and now share a camera (the others' camera sets did not change). Each
    feature's local best is the largest rank of its open half-links. Round ``t`` delivers the
    sends of round ``t - 1``: a feature keeps the largest value heard if it beats its own,
    and then sends it along its flood half-links except to the features that sent it that
    same value; round 0 sends every local best to every flood neighbour.

    Phase B (merge). Round 0: each feature whose cluster's best link is its own sends it to
    the far end. Round 1: a link sent from both ends (the best of both clusters) merges
    them. The relabel of each old cluster spreads from its merge end along its flood links
    (as in phase A, fixed until the merge): breadth-first, a feature at distance ``d``
    applies it in round ``1 + d``, forwards it to its flood neighbours except those at
    distance ``d - 1`` (all of which sent it to it in that round), and sends ``sync-x`` on
    its open half-links whose far end is not in the merged cluster; both land in round
    ``2 + d``. The phase ends in the round of the last delivery.

    Messages: the sends of one kind in one round grouped by sender-receiver pair, one
    message each, ``12`` bytes plus the entries at their wire sizes (:mod:`..sync`, payloads):
    ``sync-best`` ``12 + 2 id``, ``sync-merge`` ``8 + 2 id``, ``sync-relabel``
    ``4 + 2 id + ⌈n/8⌉``, ``sync-x`` ``4 + id + ⌈n/8⌉``; counted with
    :meth:`~pipeline.transport.Transport.count` per kind.

Memory
    A robot's fixed arrays never change size; it holds ``8 + 8 ⌈n/64⌉`` bytes per camera set
    of a cluster of two or more features that it uses (own clusters, far ends of open
    links), pruned at the start of phase A; within a phase the set only grows, so the
    robot-by-robot peak is at the end of a phase B, when it holds the pruned set plus the
    new labels it learnt (own merged clusters, ``sync-x`` received). Those are counted
    here per robot and Borůvka round: the same peak per robot.

Equivalence (tested: ``tests/pipeline/consistency/test_sync_batched.py``, Hypothesis): the
same per-robot final state (``label``, ``other``, ``open``, ``tree``, ``w``, camera sets,
``link_alive``, the deletion log, ``component``, peak memory), the same rounds, and the same
messages and bytes per kind as :func:`run_sync`.

Where it applies (:func:`sync_batched_applies`): the in-process :class:`Network` with no
fault switch, robots freshly equipped by :func:`.sync.equip_sync` with one flood graph,
every link held by both ends (alive at both or at neither) with the same weight at both.
Elsewhere :func:`run_sync_batched` runs the robots one by one (:func:`run_sync`).

Cost: ``O((H + M) log H)`` per Borůvka round (``H`` half-links, ``M`` features) plus, per
network round, work in proportion to that round's sends; camera-set tests ``O(K ⌈n/64⌉)`` for the ``K`` open links
whose clusters merged, in chunks of :data:`CHUNK` words.
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency.cycles import cycle_support_rows, support_term
from pipeline.consistency.engines.phases import run_quiet_phase
from pipeline.consistency.evidence import TRIANGLE_WEIGHT
from pipeline.consistency.keys import EMPTY, isin_sorted, ranges, tie_key, unique
from pipeline.consistency.robot import Robot
from pipeline.consistency.sync import (
    _BITS,
    BEST,
    EXCHANGE,
    MERGE,
    RELABEL,
    SUPPORT,
    exchange_step,
    finish_sync,
    has_best,
    merge_step,
    start_exchange,
    start_merge,
    start_support,
    support_step,
)
from pipeline.errors import StageStalledError
from pipeline.transport import HEADER_BYTES, Transport
from pipeline.transport.simulated import Network

__all__ = ["run_sync", "run_sync_batched", "sync_batched_applies"]

#: entries (or 64-bit words) of one vectorized piece: triangle counts, camera-set tests
CHUNK = 1 << 22


def _fresh(rb: Robot) -> bool:
    """The robot's ``sync`` state is as :func:`.sync.equip_sync` left it."""
    st = getattr(rb, "sync", None)
    if st is None:
        return False
    far = rb.offsets[rb.link_nbr] + rb.link_s.astype(np.int64)
    return bool(np.array_equal(st.label, rb.gid0 + np.arange(rb.m)) and np.array_equal(st.other, far)
                and np.array_equal(st.open, rb.link_alive) and not st.tree.any()
                and not st.cams and not st.has_best.any() and not st.relabeled.any())


class _Team:
    """Every robot's link table stacked: half-link ``h`` is row ``h - base[i]`` of robot
    ``i``; arrays ``rob``, ``nbr``, ``f`` (own global feature), ``g`` (far one), ``alive``,
    ``weight``; ``twin`` the far end's row of the same link; ``pair`` a number per
    sender-receiver pair, nondecreasing in ``h`` (tables are sorted by neighbour)."""

    def __init__(self, robots: list[Robot]) -> None:
        rb0 = robots[0]
        self.n = n = len(robots)
        self.offsets = rb0.offsets
        self.M = M = int(rb0.m_total)
        st0 = rb0.sync
        self.flood, self.id_bytes = st0.flood, st0.ids.itemsize
        self.wire_cams, self.words = st0.wire_cams, st0.words
        sizes = np.array([rb.link_r.size for rb in robots], dtype=np.int64)
        self.base = np.concatenate([[0], np.cumsum(sizes)])
        self.H = H = int(self.base[-1])
        self.rob = np.repeat(np.arange(n, dtype=np.int64), sizes)
        self.nbr = np.concatenate([rb.link_nbr for rb in robots]).astype(np.int64)
        r = np.concatenate([rb.link_r for rb in robots]).astype(np.int64)
        s = np.concatenate([rb.link_s for rb in robots]).astype(np.int64)
        self.f = self.offsets[self.rob] + r
        self.g = self.offsets[self.nbr] + s
        self.alive = np.concatenate([rb.link_alive for rb in robots])
        self.weight = np.concatenate([rb.sync.weight for rb in robots])
        self.cam = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.offsets))
        key = self.f * M + self.g
        order = np.argsort(key)
        ks = key[order]
        want = self.g * M + self.f
        pos = np.minimum(np.searchsorted(ks, want), max(H - 1, 0))
        self.twin = order[pos]
        fj = np.sort(self.f * n + self.nbr)  # one link per feature and neighbour (Ass. 2.2)
        self.symmetric = bool(H == 0 or (
            (ks[pos] == want).all() and (fj[1:] != fj[:-1]).all()
            and np.array_equal(self.alive, self.alive[self.twin])))
        pk = self.rob * n + self.nbr
        self.pair = np.concatenate([[0], np.cumsum(pk[1:] != pk[:-1])]) if H else EMPTY
        self.pairs = unique(pk[self.alive]) if H else EMPTY
        self.by_f = np.argsort(self.f, kind="stable")  # half-links by own feature

    def messages(self, S: np.ndarray) -> int:
        """Messages of one kind in one round: distinct sender-receiver pairs of the sorted
        half-links ``S``."""
        if S.size == 0:
            return 0
        p = self.pair[S]
        return 1 + int(np.count_nonzero(p[1:] != p[:-1]))

    def csr(self, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Half-links of ``mask`` grouped by own feature: ``(half-links, ptr)``, the
        half-links of feature ``x`` at ``ptr[x]:ptr[x+1]``."""
        hl = self.by_f[mask[self.by_f]]
        ptr = np.zeros(self.M + 1, dtype=np.int64)
        np.cumsum(np.bincount(self.f[hl], minlength=self.M), out=ptr[1:])
        return hl, ptr


class _Counts:
    """Messages and bytes per kind, and the rounds of the run."""

    def __init__(self) -> None:
        self.messages: dict[str, int] = {}
        self.bytes: dict[str, int] = {}

    def add(self, kind: str, messages: int, nbytes: int) -> None:
        if messages:
            self.messages[kind] = self.messages.get(kind, 0) + messages
            self.bytes[kind] = self.bytes.get(kind, 0) + HEADER_BYTES * messages + nbytes


class _Cams:
    """Camera bit sets of the clusters of two or more features, by label (a cluster of one
    feature ``g``: the camera of ``g``); rows in a growing buffer, compacted when half dead."""

    def __init__(self, team: _Team) -> None:
        self.team = team
        self.row = np.full(team.M, -1, dtype=np.int64)
        self.bits = np.zeros((64, team.words), dtype=_BITS)
        self.used = 0

    def of(self, labels: np.ndarray) -> np.ndarray:
        out = np.zeros((labels.size, self.team.words), dtype=_BITS)
        rows = self.row[labels]
        held = rows >= 0
        out[held] = self.bits[rows[held]]
        k = np.flatnonzero(~held)
        c = self.team.cam[labels[k]]
        out[k, c >> 6] = np.left_shift(np.uint64(1), (c & 63).astype(np.uint64))
        return out

    def share(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Do clusters ``a[k]`` and ``b[k]`` share a camera? (K,) bool."""
        cam = self.team.cam
        out = cam[a] == cam[b]
        ra, rb = self.row[a], self.row[b]
        step = max(1, CHUNK // max(self.team.words, 1))
        for sel, ca, cb in (((ra >= 0) & (rb >= 0), None, None), ((ra >= 0) & (rb < 0), None, b),
                            ((ra < 0) & (rb >= 0), a, None)):
            k = np.flatnonzero(sel)
            for p in range(0, k.size, step):
                kk = k[p:p + step]
                if ca is None and cb is None:
                    out[kk] = (self.bits[ra[kk]] & self.bits[rb[kk]]).any(axis=1)
                else:
                    rows = ra[kk] if cb is not None else rb[kk]
                    c = cam[(cb if cb is not None else ca)[kk]]
                    out[kk] = ((self.bits[rows, c >> 6] >> (c & 63).astype(np.uint64))
                               & np.uint64(1)).astype(bool)
        return out

    def merge(self, a: np.ndarray, b: np.ndarray) -> None:
        """Clusters ``a[k]`` and ``b[k]`` become one, labelled ``min``."""
        new_bits = self.of(a) | self.of(b)
        self.row[a] = -1
        self.row[b] = -1
        if self.used + a.size > self.bits.shape[0]:
            live = np.flatnonzero(self.row >= 0)
            keep = self.bits[self.row[live]]
            cap = max(64, 2 * (live.size + a.size))
            self.bits = np.zeros((cap, self.team.words), dtype=_BITS)
            self.bits[:live.size] = keep
            self.row[live] = np.arange(live.size)
            self.used = live.size
        self.bits[self.used:self.used + a.size] = new_bits
        self.row[np.minimum(a, b)] = self.used + np.arange(a.size)
        self.used += a.size


def sync_batched_applies(robots: list[Robot], network: Transport) -> bool:
    """True where the batched evaluation gives the robot-by-robot results: the in-process
    simulator with no fault on, and robots freshly equipped with one flood graph."""
    return (type(network) is Network and not network.faulty and len(robots) > 0
            and len({rb.sync.flood for rb in robots if hasattr(rb, "sync")}) == 1
            and all(_fresh(rb) for rb in robots))


def _support(team: _Team, counts: _Counts) -> tuple[int, np.ndarray]:
    """Phase 0: the messages, and every half-link's ``w`` as its robot computes it."""
    M, H = team.M, team.H
    A = np.flatnonzero(team.alive)
    deg = np.bincount(team.f[A], minlength=M)
    keys = unique(team.pair[A] * M + team.f[A])  # (message, own feature listed)
    msgs = int(unique(keys // M).size)
    counts.add(SUPPORT, msgs, 8 * keys.size + team.id_bytes * int(deg[keys % M].sum()))
    # τ: the far feature's list entries linked to the own feature
    adj, ptr = team.csr(team.alive)
    akeys = np.sort(team.f[A] * M + team.g[A])
    ckeys = np.sort(team.f[A] * team.n + team.nbr[A])  # (own feature, camera it links into)
    tau = np.zeros(H, dtype=np.int64)
    shared = np.zeros(H, dtype=np.int64)
    cnt = deg[team.g[A]]
    done = np.cumsum(cnt)
    start = 0
    while start < A.size:  # pieces of about CHUNK list entries
        before = int(done[start - 1]) if start else 0
        stop = max(start + 1, int(np.searchsorted(done, before + CHUNK, side="right")))
        h, c = A[start:stop], cnt[start:stop]
        x = team.g[adj[ranges(ptr[team.g[h]], ptr[team.g[h] + 1])]]
        hit = isin_sorted(np.repeat(team.f[h], c) * M + x, akeys)
        tau[h] = np.bincount(np.repeat(np.arange(h.size), c)[hit], minlength=h.size)
        hit = isin_sorted(np.repeat(team.f[h], c) * team.n + team.cam[x], ckeys)
        shared[h] = np.bincount(np.repeat(np.arange(h.size), c)[hit], minlength=h.size)
        start = stop
    quad = _quadrangles(team, tau, adj, ptr)
    stepped = np.zeros(team.n, dtype=bool)  # robots that receive a support message
    stepped[team.nbr[A]] = True
    w = np.where(stepped[team.rob],
                 team.weight + TRIANGLE_WEIGHT * support_term(tau, shared, quad), team.weight)
    # each robot holds every list it received until its quadrangles are decided (int64
    # feature, degree and far ends, as :func:`..sync.support_step` keeps them)
    ukeys, first = np.unique(team.pair[A] * M + team.f[A], return_index=True)
    dst = team.nbr[A][first]
    team.lists_bytes = (16 * np.bincount(dst, minlength=team.n)
                        + 8 * np.bincount(dst, weights=deg[ukeys % M], minlength=team.n)
                        ).astype(np.int64)
    return (1 if msgs else 0), w


def _quadrangles(team: _Team, tau: np.ndarray, adj: np.ndarray, ptr: np.ndarray) -> np.ndarray:
    """Every alive half-link's quadrangle flag (:func:`..cycles.cycle_support`), as its robot
    decides it from its own links and the lists of the support round: the lists a robot
    receives are its neighbours' features' alive links, i.e. the alive graph's rows, so one
    evaluation per link on those rows gives both halves' flags."""
    quad = np.zeros(team.H, dtype=bool)
    A = np.flatnonzero(team.alive & (tau == 0))
    rep = A[A < team.twin[A]]
    if rep.size == 0:
        return quad
    offsets = team.offsets

    def camera_of(g):
        return np.searchsorted(offsets, np.asarray(g), side="right") - 1

    # the alive graph's rows, every feature's: what the robots hold after the support round
    rows = (np.arange(team.M, dtype=np.int64), ptr, team.g[adj])
    _, q = cycle_support_rows(team.f[rep], team.g[rep], rows, rows, camera_of)
    quad[rep] = q
    quad[team.twin[rep]] = q
    return quad


def _ranks(team: _Team, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rank of every alive link by its key ``(w, -t, -lo, -hi)`` (larger is better; ``t`` =
    :func:`pipeline.consistency.keys.tie_key`), on both halves; and the representative
    half-link of each rank."""
    A = np.flatnonzero(team.alive)
    rep = A[A < team.twin[A]]
    lo, hi = np.minimum(team.f[rep], team.g[rep]), np.maximum(team.f[rep], team.g[rep])
    rep = rep[np.lexsort((-hi, -lo, ~tie_key(lo, hi), w[rep]))]
    rank = np.full(team.H, -1, dtype=np.int64)
    rank[rep] = np.arange(rep.size)
    rank[team.twin[rep]] = np.arange(rep.size)
    return rank, rep


def _flood_best(team: _Team, best: np.ndarray, fl: np.ndarray, fptr: np.ndarray,
                counts: _Counts, cap: int) -> int:
    """Phase A's max-flood of ``best`` (per feature, in place); returns its rounds."""
    f, g, twin = team.f, team.g, team.twin
    entry = 12 + 2 * team.id_bytes
    S = np.sort(fl[ranges(fptr[:-1][best >= 0], fptr[1:][best >= 0])])
    t = 0
    while S.size:
        counts.add(BEST, team.messages(S), entry * S.size)
        t += 1
        if t > cap:
            raise StageStalledError(f"sync phase did not end within {cap} rounds")
        val, tgt = best[f[S]], g[S]
        ut, inv = np.unique(tgt, return_inverse=True)
        top = np.full(ut.size, -1, dtype=np.int64)
        np.maximum.at(top, inv, val)
        up = top > best[ut]
        G = ut[up]
        best[G] = top[up]
        skip = np.sort(twin[S[up[inv] & (val == best[tgt])]])  # they hold it already
        S = fl[ranges(fptr[G], fptr[G + 1])]
        S = np.sort(S[~isin_sorted(S, skip)])
    return t


def run_sync_batched(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """The ``sync`` rule on every robot, evaluated in batch; returns what
    :func:`run_sync` returns (``rounds``, ``boruvka_rounds``, ``support_rounds``) and
    leaves every robot and the network as it does. Runs the robots one by one where the
    batched evaluation does not apply (:func:`sync_batched_applies`)."""
    if not sync_batched_applies(robots, network):
        return run_sync(robots, network, on_round=on_round)
    team = _Team(robots)
    if not team.symmetric or any(not network.is_neighbour(int(p // team.n), int(p % team.n))
                                 for p in team.pairs.tolist()):
        return run_sync(robots, network, on_round=on_round)
    counts = _Counts()
    # the rounds are counted as the batch evaluates them and reported then (a long run shows
    # its progress while it computes); the network's clock is advanced at the end
    told = 0

    def tell(upto: int) -> None:
        nonlocal told
        if on_round is not None:
            for k in range(told + 1, upto + 1):
                on_round(k)
        told = max(told, upto)

    support_rounds, w = _support(team, counts)
    tell(support_rounds)
    A = np.flatnonzero(team.alive)
    if not np.array_equal(w[A], w[team.twin[A]]):  # the ends disagree on a weight
        return run_sync(robots, network, on_round=on_round)
    n, M, H = team.n, team.M, team.H
    f, g, rob, nbr, twin, alive = team.f, team.g, team.rob, team.nbr, team.twin, team.alive
    rank, rep_of_rank = _ranks(team, w)
    cap = 2 * n + 4
    label = np.arange(M, dtype=np.int64)
    size = np.ones(M, dtype=np.int64)
    is_open = alive.copy()
    tree = np.zeros(H, dtype=bool)
    frozen = np.full(H, -1, dtype=np.int64)  # far label of a link closed as ineligible
    dirty = alive.copy()
    cams = _Cams(team)
    held_max = np.zeros(n, dtype=np.int64)  # camera sets held at a phase B's end, largest
    t, boruvka = support_rounds, 0
    x_entry = 4 + team.id_bytes + team.wire_cams
    r_entry = 4 + 2 * team.id_bytes + team.wire_cams
    while True:
        # phase A: close, local bests, max-flood
        is_open &= label[f] != label[g]
        k = np.flatnonzero(is_open & dirty)
        k = k[cams.share(label[f[k]], label[g[k]])]
        is_open[k] = False
        frozen[k] = label[g[k]]
        dirty[:] = False
        best = np.full(M, -1, dtype=np.int64)
        op = np.flatnonzero(is_open)
        np.maximum.at(best, f[op], rank[op])
        fmask = (tree & alive) if team.flood == "tree" else (alive & (label[f] == label[g]))
        fl, fptr = team.csr(fmask)
        t += _flood_best(team, best, fl, fptr, counts, cap)
        tell(t)
        if not (best >= 0).any():
            break
        boruvka += 1
        if boruvka > M:
            raise StageStalledError(f"sync did not end within {M} Borůvka rounds")
        # camera sets held after phase A's prune: clusters of two or more in use
        own = np.flatnonzero(size[label] >= 2)
        far_op = op[size[label[g[op]]] >= 2]
        held = [team.cam[own] * M + label[own], rob[far_op] * M + label[g[far_op]]]
        # phase B: merge messages, mutual bests merge
        v = np.flatnonzero(best >= 0)
        r = rep_of_rank[best[v]]
        mine = np.where(f[r] == v, r, np.where(f[twin[r]] == v, twin[r], -1))
        Hm = np.sort(mine[mine >= 0])
        counts.add(MERGE, team.messages(Hm), (8 + 2 * team.id_bytes) * Hm.size)
        Mh = Hm[best[g[Hm]] == rank[Hm]]  # the best of both clusters: both halves here
        one = Mh[f[Mh] < g[Mh]]
        a, b = label[f[one]], label[g[one]]
        lab_new = np.arange(M, dtype=np.int64)
        lab_new[a] = lab_new[b] = np.minimum(a, b)
        new = lab_new[label]
        merged_lab = np.zeros(M, dtype=bool)
        merged_lab[a] = merged_lab[b] = True
        memb = merged_lab[label]
        held.append(team.cam[memb] * M + new[memb])
        # the relabel floods, breadth-first from the merge ends, with sync-x
        ol, optr = team.csr(is_open)
        dist = np.full(M, -1, dtype=np.int64)
        V = np.sort(f[Mh])
        dist[V] = 0
        d, last = 0, 1
        while V.size:
            E = fl[ranges(fptr[V], fptr[V + 1])]
            u = g[E]
            if d:
                keep = dist[u] != d - 1
                E, u = E[keep], u[keep]
            E = np.sort(E)
            X = ol[ranges(optr[V], optr[V + 1])]
            X = np.sort(X[new[g[X]] != new[f[X]]])
            counts.add(RELABEL, team.messages(E), r_entry * E.size)
            counts.add(EXCHANGE, team.messages(X), x_entry * X.size)
            held.append(nbr[X] * M + new[f[X]])
            if E.size or X.size:
                last = 2 + d
            V = unique(u[dist[u] == -1])
            d += 1
            dist[V] = d
        if last > cap:
            raise StageStalledError(f"sync phase did not end within {cap} rounds")
        t += last
        tell(t)
        keys = unique(np.concatenate(held))
        held_max = np.maximum(held_max, np.bincount(keys // M, minlength=n))
        # apply the merges
        cams.merge(a, b)
        size[np.minimum(a, b)] = size[a] + size[b]
        label = new
        tree[Mh] = True
        dirty = is_open & (memb[f] | memb[g])
    for _ in range(t):
        network.end_round()
    tell(t)
    for kind, m in counts.messages.items():
        network.count(kind, m, counts.bytes[kind])
    # every robot's state, then its own cut
    other = np.where(frozen >= 0, frozen, np.where(alive, label[g], g))
    per_set = 8 + 8 * team.words
    for i, rb in enumerate(robots):
        st = rb.sync
        hs = slice(int(team.base[i]), int(team.base[i + 1]))
        fs = slice(int(team.offsets[i]), int(team.offsets[i + 1]))
        st.label = label[fs].copy()
        st.other = other[hs].copy()
        st.open = is_open[hs].copy()
        st.tree = tree[hs].copy()
        st.w = w[hs].copy()
        mine = unique(st.label[size[st.label] >= 2])
        st.cams = {int(x): row for x, row in zip(mine.tolist(), cams.of(mine), strict=True)}
        st.rounds = boruvka
        rb.peak_memory_bytes = max(rb.peak_memory_bytes,
                                   st.robot_fixed + st.fixed + int(held_max[i]) * per_set,
                                   st.robot_fixed + st.fixed + int(team.lists_bytes[i]))
        finish_sync(rb, t)
        network.note_memory(rb.id, rb.peak_memory_bytes)
    return dict(rounds=t, boruvka_rounds=boruvka, support_rounds=support_rounds)


def run_sync(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """The ``sync`` rule on every robot (each equipped by :func:`equip_sync`): support round,
    Borůvka rounds until no eligible link is left, then each robot cuts its side.

    The driver only plays the clock and the phase barrier (nothing in flight) and reads one
    bit per robot (:func:`has_best`), as the termination wave of a robot alone would.

    Returns ``rounds``, ``boruvka_rounds`` and ``support_rounds``.
    """
    n = len(robots)
    cap = 2 * n + 4
    t = run_quiet_phase(robots, network, start_support, support_step, on_round, 0, cap, "sync")
    support_rounds = t
    boruvka = 0
    m_total = robots[0].m_total if robots else 0
    while True:
        t += run_quiet_phase(robots, network, start_exchange, exchange_step, on_round, t, cap,
                             "sync")
        if not any(has_best(rb) for rb in robots):
            break
        boruvka += 1
        if boruvka > m_total:
            raise StageStalledError(f"sync did not end within {m_total} Borůvka rounds")
        t += run_quiet_phase(robots, network, start_merge, merge_step, on_round, t, cap, "sync")
    for rb in robots:
        rb.sync.rounds = boruvka
        finish_sync(rb, t)
        network.note_memory(rb.id, rb.peak_memory_bytes)  # the peak its steps measured
    return dict(rounds=t, boruvka_rounds=boruvka, support_rounds=support_rounds)
