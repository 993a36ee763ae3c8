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
    ``w = λ + TRIANGLE_WEIGHT · (τ · min(1, K / shared) + q)``: ``λ`` the link's local
    log-likelihood ratio (:mod:`pipeline.matching.link_evidence`, held by both robots of the
    link since matching), ``τ`` the number of third cameras in which both ends match one
    common feature, ``shared`` the third cameras both ends are linked into, ``K`` =
    :data:`.cycles.SUPPORT_VIEWS` (beyond ``K`` such cameras the triangles count as the
    agreement rate ``τ / shared`` over ``K`` views: on dense graphs one confusion repeats
    across views and closes many triangles, :func:`.cycles.support_term`), and
    ``q = 1`` for a link without triangle over which a quadrangle through four cameras closes
    (:mod:`.cycles`: a good link beside a pair that swapped two matches loses its triangles,
    not its quadrangle). Phase 0 (*support*, one round): every robot sends each linked
    neighbour the other ends of its features linked to it; both ends of a link then count
    ``τ`` and ``shared`` and decide ``q`` from the same lists (the far end's, and those of
    the features linked to its own end), once every linked neighbour's list is in. Both
    count features of the far end's list, not cameras: the links are one-to-one per camera
    pair (Assumption 2.2, checked on input), so a feature is linked into a camera through
    one feature at most and the two counts are the same.
    Order: ``(w, -t, -lo, -hi)`` decreasing (``lo < hi`` the link's global feature ids,
    ``t`` = :func:`.keys.tie_key` of them: ties of ``w`` go in a fixed pseudo-random order,
    so that a chain of equal links is not merged one pair per Borůvka round), a strict
    total order every robot evaluates alike.

A Borůvka round (two phases, each ended when nothing is in flight)
    A. *best.* Every robot closes its links whose two ends are in one cluster or whose
       clusters share a camera (*ineligible*: the merge would join two features of a camera,
       Def. 2.4; camera sets only grow, so an ineligible link stays so); the others are
       *open*. Per own cluster it takes its best open link, and the members of each cluster
       max-flood the best along the cluster's *flood links* (below): a robot forwards an
       improvement to its flood neighbours in that cluster except those it heard it from.
    B. *merge.* The ends of each cluster's best link tell each other that it is their
       cluster's best (``sync-merge``). A link that is the best of *both* its clusters
       (locally dominant) merges them: label ``min(A, B)`` (the smallest global feature id of
       the cluster), camera set ``A ∪ B``. Each end floods the relabel inside its old cluster
       along the old flood links (``sync-relabel``), and every member, in the round it
       relabels, tells the far end of each of its open links the new label and camera set
       (``sync-x``): the label exchange rides with the relabel flood, and only the clusters
       that merged send it. A cluster has one best link, so it merges at most once per
       round: the merges of one round are disjoint pairs, each conflict-free.
    The stage ends after a phase A in which no robot holds an open link. The first phase A
    needs no exchange: every cluster is one feature, named by its global id, and its camera
    set is the feature's camera, both public.

Flood links (:data:`FLOODS`, chosen per team at :func:`equip_sync`)
    ``"links"`` (default): every link with both ends in the cluster (both ends know it: each
    holds both labels); a flood crosses the cluster's link diameter in hops. ``"tree"``: the
    links that merged the cluster (its merge tree, ``|C| - 1`` links); fewer messages, but
    Borůvka's trees grow deep, and so do the floods. Measured (``bench/sync_scaling.py``,
    ``links`` against ``tree``): CMU hotel, 101 frames, complete graph, 428 rounds, 2.1 M
    messages, 444 MB against 3803 rounds, 1.8 M messages, 209 MB; the same on ``ring2``,
    1297 rounds, 127 k messages, 8 MB against 2361, 85 k, 5 MB; 3000 cameras on ``ring2``
    (30 landmarks each), 25 k rounds, 8.2 M messages, 1.6 GB against 44 k, 4.3 M, 0.8 GB
    (camera sets of ``⌈n/8⌉`` bytes dominate). ``links`` trades bytes for rounds; when the
    robots run as their own programs every round costs a packet to every neighbour (the
    round state of :class:`pipeline.transport.RoundEndpoint`), so it is the default.

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

What each end knows (the invariant the phases keep)
    At the start of every phase A, for every open or inside link both ends hold both
    clusters' current labels and camera sets, so they judge it alike: a cluster that merged
    told the far end of every open link of every member (``sync-x``), and the relabel flood
    told every member. ``sync-x`` never crosses a link whose ends just joined one cluster
    (both ends learn that from their own floods), and a link closed as ineligible never
    needs news again. A robot keeps the camera sets of the clusters of two or more features
    it uses (own clusters, far ends of open links), dropped at the start of phase A when
    no longer used.

Bounds and cost
    Rounds per Borůvka round ``≤ 2 s + 3`` with ``s`` the largest cluster's diameter along
    its flood links (``≤ n - 1``): phase A ``≤ s + 1`` (the best reaches every member within
    ``s`` hops; the last forwards land one round later), phase B ``≤ s + 2`` (merge, flood,
    the last ``sync-x``). Memory per robot ``O(L_i + m_i + (n/8) · clusters it uses)`` (its links,
    per own feature its cluster's label and best, the camera bit sets): it follows the
    links, never ``Σ |C|²``. Messages: phase 0 sends each feature's link list once per
    linked neighbour (``Σ_f deg(f)²`` ids in all); phase A, per cluster and round, the
    improved bests; phase B, a relabel per flood link of each merged cluster and a label per
    open link of it. Every start and step measures the robot's memory; within a phase it
    only grows (camera sets are dropped at phase A's start only), so its peak is at the
    end of a phase B (or of the support round).

Drivers: :func:`.engines.sync_batched.run_sync` steps the robots one by one (the reference, and the code a robot
runs alone); :func:`.sync_batched.run_sync_batched` evaluates the same rounds for all robots
at once in the simulator, with the same per-robot state, rounds, messages, bytes and memory.

Missing links are not invented: a kept association set is connected by input links; the
pairs it implies between its features (the closure) are the association's output.

Payloads (counted at their numpy ``nbytes``; ``id`` = :func:`id_dtype`, int32 below ``2**31``
features; ``nb = ⌈n/8⌉``): ``sync-support`` ``feat`` (F,) int32, ``deg`` (F,) int32, ``gid``
(D,) id; ``sync-best`` ``feat`` (K,) int32 (the receiver's feature in the cluster), ``w``
(K,) float64, ``lo``/``hi`` (K,) id; ``sync-merge`` ``w``, ``lo``, ``hi`` as for
``sync-best`` (the link names the clusters at both ends); ``sync-relabel`` ``feat`` (K,)
int32 (the receiver's), ``old`` (K, 2) id (the merged labels; the new one is the smaller),
``cams`` (K, nb) uint8; ``sync-x`` ``feat`` (K,) int32 (the sender's), ``label`` (K,) id,
``cams`` (K, nb) uint8 (a sender's features in one message are in distinct clusters).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from pipeline.consistency.cycles import cycle_support, support_term
from pipeline.consistency.evidence import TRIANGLE_WEIGHT
from pipeline.consistency.keys import isin_sorted, ranges, tie_key
from pipeline.consistency.robot import Robot
from pipeline.transport import Message

__all__ = ["SyncState", "equip_sync", "equip_robot", "start_support", "support_step", "start_exchange",
           "exchange_step", "start_merge", "merge_step", "finish_sync", "has_best",
           "id_dtype", "CASE_SYNC", "SUPPORT", "BEST", "MERGE",
           "RELABEL", "EXCHANGE", "FLOODS"]

Send = Callable[[int, str, dict], None]

#: deletion-log code of a link cut by the ``sync`` rule (next to Alg. 1's and the evidence rule's)
CASE_SYNC = 6
SUPPORT, BEST, MERGE, RELABEL, EXCHANGE = (
    "sync-support", "sync-best", "sync-merge", "sync-relabel", "sync-x")
#: the flood graphs a robot may use inside a cluster (:func:`equip_sync`)
FLOODS = ("links", "tree")
_BITS = np.dtype("<u8")  # camera bit sets: little-endian 64-bit words, bit c = camera c


def id_dtype(m_total: int) -> np.dtype:
    """Type of the global feature ids on the wire: int32, int64 from ``2**31`` features."""
    return np.dtype(np.int32 if m_total < 2**31 else np.int64)


@dataclass
class SyncState:
    """What one robot holds for the ``sync`` rule (its own links and features only).

    A cluster holds at most one feature of each camera, so the robot's own clusters are its
    own features': every per-cluster value is kept per own feature.

    Attributes
    ----------
    weight : (L,) float64 — local evidence ``λ`` of its links (link table order)
    w : (L,) float64 — ``λ + TRIANGLE_WEIGHT · support_term(τ, shared, quad)`` once the
        support round is over
    lo, hi : (L,) int64 — the link's global feature ids, ``lo < hi``
    other : (L,) int64 — cluster of each link's far end, as last heard
    open : (L,) bool — ends in different clusters and not found ineligible
    tree : (L,) bool — the link merged two clusters (their merge tree)
    label : (m,) int64 — cluster of each own feature (smallest global id of the cluster)
    has_best, best_w, best_lo, best_hi : (m,) — best eligible link known for the feature's
        cluster in this phase A (``w``, ``lo``, ``hi``; ``-inf, -1, -1`` when none)
    relabeled : (m,) bool — the feature's cluster merged in this phase B
    cams : dict label -> (⌈n/64⌉,) uint64 — camera bit sets of the clusters of two or more
        features it knows (own ones, far ends of open links); a cluster of one feature ``g``
        is ``{camera of g}``, known from the public offsets
    flood : str — flood graph inside a cluster: ``"links"`` (every link inside it) or
        ``"tree"`` (the links that merged it)
    ids : numpy dtype of the global ids on the wire (:func:`id_dtype`)
    rounds : int — Borůvka rounds taken
    fixed : int — bytes of the arrays above, whose sizes never change
    robot_fixed : int — :meth:`~.robot.Robot.fixed_bytes` of its robot (fixed sizes too)
    tau : (L,) int64 — triangle support counted so far (on a reliable channel the lists of
        the support round may arrive in several rounds)
    shared : (L,) int64 — third cameras both ends are linked into, counted so far
    quad : (L,) bool — a quadrangle closes over a link without triangle (:mod:`.cycles`),
        decided once every linked neighbour's list is in
    support_lists, support_heard — the lists received in the support round (freed once the
        quadrangles are decided) and the neighbours heard from
    """

    weight: np.ndarray
    w: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    other: np.ndarray
    open: np.ndarray
    tree: np.ndarray
    label: np.ndarray
    has_best: np.ndarray
    best_w: np.ndarray
    best_lo: np.ndarray
    best_hi: np.ndarray
    relabeled: np.ndarray
    cams: dict
    flood: str
    ids: np.dtype
    n_cams: int
    rounds: int = 0
    fixed: int = 0
    robot_fixed: int = 0
    tau: np.ndarray | None = None
    shared: np.ndarray | None = None
    quad: np.ndarray | None = None
    support_lists: list | None = None
    support_heard: set | None = None

    def __post_init__(self) -> None:
        if self.quad is None:
            self.quad = np.zeros(self.weight.shape[0], dtype=bool)
        if self.support_lists is None:
            self.support_lists = []
        if self.support_heard is None:
            self.support_heard = set()
        if self.tau is None:
            self.tau = np.zeros(self.weight.shape[0], dtype=np.int64)
        if self.shared is None:
            self.shared = np.zeros(self.weight.shape[0], dtype=np.int64)
        self.fixed = int(sum(a.nbytes for a in (
            self.weight, self.w, self.lo, self.hi, self.other, self.open, self.tree,
            self.label, self.has_best, self.best_w, self.best_lo, self.best_hi,
            self.relabeled, self.tau, self.shared, self.quad)))

    def nbytes(self) -> int:
        """Bytes held: the fixed-size arrays (``fixed``), ``8 + 8 · words`` per camera set, and
        during the support round the neighbours' lists kept for the quadrangle test."""
        lists = 0 if not self.support_lists else sum(
            int(f.nbytes + d.nbytes + g.nbytes) for _, f, d, g in self.support_lists)
        return self.fixed + len(self.cams) * (8 + 8 * self.words) + lists

    @property
    def words(self) -> int:
        """64-bit words of a camera bit set: ``⌈n/64⌉``."""
        return (self.n_cams + 63) // 64

    @property
    def wire_cams(self) -> int:
        """Bytes of one camera set on the wire: ``⌈n/8⌉``."""
        return (self.n_cams + 7) // 8


def equip_sync(robot: Robot, link_weight, flood: str = "links") -> None:
    """Give a robot its ``sync`` state: the local evidence of its link table rows, and the
    flood graph inside a cluster (:data:`FLOODS`; every robot of a team uses the same)."""
    if flood not in FLOODS:
        raise ValueError(f"flood must be one of {FLOODS}, not {flood!r}")
    w = np.asarray(link_weight, dtype=np.float64).reshape(-1)
    own = robot.gid0 + robot.link_r.astype(np.int64)
    far = robot.offsets[robot.link_nbr] + robot.link_s.astype(np.int64)
    L, m = w.shape[0], robot.m
    robot.sync = SyncState(
        weight=w, w=w.copy(), lo=np.minimum(own, far), hi=np.maximum(own, far), other=far,
        open=robot.link_alive.copy(), tree=np.zeros(L, dtype=bool),
        label=robot.gid0 + np.arange(m, dtype=np.int64), has_best=np.zeros(m, dtype=bool),
        best_w=np.full(m, -np.inf), best_lo=np.full(m, -1, dtype=np.int64),
        best_hi=np.full(m, -1, dtype=np.int64), relabeled=np.zeros(m, dtype=bool),
        cams={},
        flood=flood, ids=id_dtype(robot.m_total), n_cams=robot.n,
        robot_fixed=robot.fixed_bytes())


def equip_robot(robot: Robot, link_weight, keypoints=None, projection=None) -> None:
    """The registry's ``equip`` (:mod:`.rules`): the rule uses the links' evidence only."""
    equip_sync(robot, link_weight)


def _measure(robot: Robot) -> None:
    st = robot.sync
    robot.peak_memory_bytes = max(robot.peak_memory_bytes, st.robot_fixed + st.nbytes())


# --------------------------------------------------------------------------- helpers


def _camera(robot: Robot, gid: np.ndarray) -> np.ndarray:
    """Camera of global feature ids (public offsets)."""
    return np.searchsorted(robot.offsets, gid, side="right") - 1


def _by_nbr(robot: Robot, k: np.ndarray) -> Iterator[tuple[int, slice]]:
    """Runs of ascending link indices ``k`` with one neighbour each (the table is sorted by
    neighbour): ``(neighbour, slice of k)``."""
    if k.size == 0:
        return
    nbr = robot.link_nbr[k]
    cut = np.flatnonzero(nbr[1:] != nbr[:-1]) + 1
    bounds = [0, *cut.tolist(), k.size]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        yield int(nbr[a]), slice(a, b)


def _cams(robot: Robot, labels: np.ndarray) -> np.ndarray:
    """Camera bit sets of clusters ``labels``, (K, words) uint64."""
    st = robot.sync
    out = np.zeros((labels.size, st.words), dtype=_BITS)
    for i, g in enumerate(labels.tolist()):
        row = st.cams.get(g)
        if row is None:
            c = int(np.searchsorted(robot.offsets, g, side="right")) - 1
            out[i, c >> 6] = np.uint64(1 << (c & 63))
        else:
            out[i] = row
    return out


def _has_camera(bits: np.ndarray, c: np.ndarray) -> np.ndarray:
    return ((bits[np.arange(c.size), c >> 6] >> (c & 63).astype(np.uint64)) & 1).astype(bool)


def _overlap(robot: Robot, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Do clusters ``a[k]`` and ``b[k]`` share a camera (Def. 2.4)? (K,) bool."""
    st = robot.sync
    ca, cb = _camera(robot, a), _camera(robot, b)
    out = ca == cb  # two clusters of one feature each
    if not st.cams or a.size == 0:
        return out
    held = np.fromiter(st.cams, dtype=np.int64, count=len(st.cams))
    order = np.argsort(held)
    held, bits = held[order], np.stack(list(st.cams.values()))[order]
    pa = np.minimum(np.searchsorted(held, a), held.size - 1)
    pb = np.minimum(np.searchsorted(held, b), held.size - 1)
    ra, rb = np.where(held[pa] == a, pa, -1), np.where(held[pb] == b, pb, -1)
    k = np.flatnonzero((ra >= 0) & (rb >= 0))
    out[k] = (bits[ra[k]] & bits[rb[k]]).any(axis=1)
    k = np.flatnonzero((ra >= 0) & (rb < 0))
    out[k] = _has_camera(bits[ra[k]], cb[k])
    k = np.flatnonzero((ra < 0) & (rb >= 0))
    out[k] = _has_camera(bits[rb[k]], ca[k])
    return out


def _keep_cams(st: SyncState, labels: np.ndarray, bits: np.ndarray) -> None:
    """Hold the camera sets ``bits`` of clusters ``labels`` (replacing older ones)."""
    for g, row in zip(labels.tolist(), bits, strict=True):
        st.cams[g] = row.copy()


def _to_wire(st: SyncState, bits: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(bits.view(np.uint8)[:, :st.wire_cams])


def _from_wire(st: SyncState, rows: np.ndarray) -> np.ndarray:
    out = np.zeros((rows.shape[0], 8 * st.words), dtype=np.uint8)
    out[:, :rows.shape[1]] = rows
    return out.view(_BITS)


def _best_per(group: np.ndarray, w, lo, hi) -> np.ndarray:
    """Index of the largest key ``(w, -t, -lo, -hi)`` of each group (``t`` =
    :func:`.keys.tie_key`), groups ascending."""
    order = np.lexsort((-hi, -lo, ~tie_key(lo, hi), w, group))
    g = group[order]
    last = np.ones(g.size, dtype=bool)
    last[:-1] = g[1:] != g[:-1]
    return order[last]


def _flood_mask(robot: Robot) -> np.ndarray:
    """Own links along which the robot floods inside its clusters (:data:`FLOODS`)."""
    st = robot.sync
    if st.flood == "tree":
        return st.tree & robot.link_alive
    return robot.link_alive & (st.label[robot.link_r] == st.other)


# --------------------------------------------------------------------------- phase 0: support


def start_support(robot: Robot, send: Send) -> None:
    """Send each linked neighbour the far ends of every own feature linked to it."""
    st = robot.sync
    k = np.flatnonzero(robot.link_alive)
    r = robot.link_r[k]
    far = robot.offsets[robot.link_nbr[k]] + robot.link_s[k].astype(np.int64)
    order = np.argsort(r, kind="stable")
    adj = far[order]  # far ends grouped by own feature (table order within a feature)
    ptr = np.concatenate([[0], np.cumsum(np.bincount(r, minlength=robot.m))])
    for j, s in _by_nbr(robot, k):
        feats = np.unique(r[s])
        send(j, SUPPORT, {"feat": feats.astype(np.int32),
                          "deg": (ptr[feats + 1] - ptr[feats]).astype(np.int32),
                          "gid": adj[ranges(ptr[feats], ptr[feats + 1])].astype(st.ids)})
    _measure(robot)


def support_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """Count each link's triangle support ``τ`` and the third cameras both ends are linked
    into (``shared``) from the far end's list; set ``w`` (:func:`.cycles.support_term`)."""
    st = robot.sync
    alive = robot.link_alive
    far = robot.offsets[robot.link_nbr] + robot.link_s.astype(np.int64)
    m_total = np.int64(robot.m_total)
    own_keys = np.sort(robot.link_r[alive].astype(np.int64) * m_total + far[alive])
    tau = st.tau
    n = np.int64(robot.n)
    own_cams = np.sort(robot.link_r[alive].astype(np.int64) * n + robot.link_nbr[alive])
    bounds = np.searchsorted(robot.link_nbr, [[m.src for m in inbox], [m.src + 1 for m in inbox]])
    for msg, a, b in zip(inbox, bounds[0].tolist(), bounds[1].tolist(), strict=True):
        if msg.kind != SUPPORT:
            continue
        p = msg.payload
        feats, deg = p["feat"].astype(np.int64), p["deg"].astype(np.int64)
        st.support_lists.append((msg.src, feats, deg, p["gid"].astype(np.int64)))
        st.support_heard.add(int(msg.src))
        links = a + np.flatnonzero(alive[a:b])
        if links.size == 0 or feats.size == 0:
            continue
        starts = np.concatenate([[0], np.cumsum(deg)])
        s = robot.link_s[links]
        pos = np.minimum(np.searchsorted(feats, s), feats.size - 1)
        ok = feats[pos] == s
        links, pos = links[ok], pos[ok]
        rep = np.repeat(links, deg[pos])
        idx = ranges(starts[pos], starts[pos + 1])
        keys = robot.link_r[rep].astype(np.int64) * m_total + p["gid"][idx].astype(np.int64)
        tau += np.bincount(rep[isin_sorted(keys, own_keys)], minlength=tau.size)
        cams = _camera(robot, p["gid"][idx].astype(np.int64))
        st.shared += np.bincount(rep[isin_sorted(robot.link_r[rep].astype(np.int64) * n + cams,
                                                 own_cams)], minlength=tau.size)
    expected = set(np.unique(robot.link_nbr[alive]).tolist())
    if st.support_lists and expected <= st.support_heard:
        _measure(robot)  # the peak, with every list held
        st.quad = _quadrangles(robot, st)
        st.support_lists = []
    st.w = st.weight + TRIANGLE_WEIGHT * support_term(tau, st.shared, st.quad)
    _measure(robot)


def _quadrangles(robot: Robot, st: SyncState) -> np.ndarray:
    """Quadrangle flag of the own links without triangle (:func:`.cycles.cycle_support`),
    from the own links and the lists every linked neighbour sent in the support round."""

    alive = robot.link_alive
    quad = np.zeros(robot.link_r.shape[0], dtype=bool)
    sel = np.flatnonzero(alive & (st.tau == 0))
    if sel.size == 0:
        return quad
    far = robot.offsets[robot.link_nbr] + robot.link_s.astype(np.int64)
    lists: dict[int, np.ndarray] = {}
    for src, feats, deg, gid in st.support_lists:
        starts = np.concatenate([[0], np.cumsum(deg)])
        base = int(robot.offsets[src])
        for f, a, b in zip(feats.tolist(), starts[:-1].tolist(), starts[1:].tolist(),
                           strict=True):
            lists[base + f] = gid[a:b]
    k = np.flatnonzero(alive)
    order = np.argsort(robot.link_r[k], kind="stable")
    rk, fk = robot.link_r[k][order], far[k][order]
    cut = np.flatnonzero(np.diff(rk)) + 1
    own_lists = {robot.gid0 + int(r[0]): f for r, f in zip(np.split(rk, cut), np.split(fk, cut),
                                                          strict=True) if r.size}
    offsets = robot.offsets

    def camera_of(g):
        return np.searchsorted(offsets, np.asarray(g), side="right") - 1

    _, q = cycle_support(robot.gid0 + robot.link_r[sel].astype(np.int64), far[sel], lists,
                         own_lists, camera_of)
    quad[sel] = q
    return quad


# --------------------------------------------------------------------------- phase A


def _send_best(robot: Robot, feats: np.ndarray, send: Send, skip: np.ndarray | None = None) -> None:
    """Send the best of the clusters of own features ``feats`` (bool mask) along their flood
    links, except to the ``(feature · n + neighbour)`` pairs in ``skip`` (sorted)."""
    st = robot.sync
    k = np.flatnonzero(_flood_mask(robot) & feats[robot.link_r])
    if skip is not None and skip.size and k.size:
        k = k[~isin_sorted(robot.link_r[k].astype(np.int64) * robot.n + robot.link_nbr[k], skip)]
    if k.size == 0:
        return
    r, feat = robot.link_r[k], robot.link_s[k]
    w, lo, hi = st.best_w[r], st.best_lo[r].astype(st.ids), st.best_hi[r].astype(st.ids)
    for j, s in _by_nbr(robot, k):
        send(j, BEST, {"feat": feat[s], "w": w[s], "lo": lo[s], "hi": hi[s]})


def start_exchange(robot: Robot, send: Send) -> None:
    """Phase A, round 0: close the links inside a cluster or ineligible (Def. 2.4: their
    clusters share a camera), take each own cluster's best open link and flood it."""
    st = robot.sync
    st.relabeled[:] = False
    st.has_best[:] = False
    st.best_w[:], st.best_lo[:], st.best_hi[:] = -np.inf, -1, -1
    own = st.label[robot.link_r]
    st.open &= robot.link_alive & (own != st.other)
    k = np.flatnonzero(st.open)
    st.open[k[_overlap(robot, own[k], st.other[k])]] = False
    if st.cams:  # hold the camera sets of the clusters still in use only
        used = set(st.label.tolist()) | set(st.other[st.open].tolist())
        st.cams = {g: row for g, row in st.cams.items() if g in used}
    k = np.flatnonzero(st.open)
    if k.size:
        r = robot.link_r[k]
        top = k[_best_per(r, st.w[k], st.lo[k], st.hi[k])]
        r = robot.link_r[top]
        st.has_best[r] = True
        st.best_w[r], st.best_lo[r], st.best_hi[r] = st.w[top], st.lo[top], st.hi[top]
        _send_best(robot, st.has_best, send)
    _measure(robot)


def exchange_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """Phase A: keep the best heard for each own cluster; forward an improvement along the
    flood links, except back to the neighbours it came from."""
    st = robot.sync
    msgs = [m for m in inbox if m.kind == BEST]
    if msgs:
        src, f, w, lo, hi = _gather(msgs, ("feat", "w", "lo", "hi"))
        # per feature the largest of the keys heard and the one held (held wins a tie); a
        # feature that holds none takes the largest heard (a link of evidence -inf included)
        h = f[st.has_best[f]]
        top = _best_per(np.concatenate([f, h]), np.concatenate([w, st.best_w[h]]),
                        np.concatenate([lo, st.best_lo[h]]), np.concatenate([hi, st.best_hi[h]]))
        top = top[top < f.size]
        if top.size:
            g = f[top]
            st.has_best[g] = True
            st.best_w[g], st.best_lo[g], st.best_hi[g] = w[top], lo[top], hi[top]
            improved = np.zeros(robot.m, dtype=bool)
            improved[g] = True
            same = improved[f] & (w == st.best_w[f]) & (lo == st.best_lo[f]) & (hi == st.best_hi[f])
            _send_best(robot, improved, send, np.sort(f[same] * robot.n + src[same]))
    _measure(robot)


def has_best(robot: Robot) -> bool:
    """After phase A: does some own cluster hold an eligible link?"""
    return bool(robot.sync.has_best.any())


# --------------------------------------------------------------------------- phase B


def start_merge(robot: Robot, send: Send) -> None:
    """Phase B, round 0: tell the far end of each own cluster's best link that it is."""
    st = robot.sync
    f = np.flatnonzero(st.has_best)
    gid = robot.gid0 + f
    f = f[(st.best_lo[f] == gid) | (st.best_hi[f] == gid)]
    far = st.best_lo[f] + st.best_hi[f] - (robot.gid0 + f)
    cam = _camera(robot, far)
    k = robot.find_links(cam, far - robot.offsets[cam])
    order = np.argsort(k)
    k, f = k[order], f[order]
    w, lo, hi = st.best_w[f], st.best_lo[f].astype(st.ids), st.best_hi[f].astype(st.ids)
    for j, s in _by_nbr(robot, k):
        send(j, MERGE, {"w": w[s], "lo": lo[s], "hi": hi[s]})
    _measure(robot)


def merge_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """Phase B: merge along locally dominant links, flood each relabel inside the old
    cluster, and tell the far ends of the open links the new cluster (``sync-x``)."""
    st = robot.sync
    xs, merges, rels = [], [], []
    for msg in inbox:
        (xs if msg.kind == EXCHANGE else merges if msg.kind == MERGE
         else rels if msg.kind == RELABEL else []).append(msg)
    if xs:  # the far ends' new clusters
        src, feat, label, rows = _gather(xs, ("feat", "label", "cams"))
        k = robot.find_links(src, feat)
        ok = k >= 0
        st.other[k[ok]] = label[ok]
        _keep_cams(st, label[ok], _from_wire(st, rows[ok]))
    if not (merges or rels):
        _measure(robot)
        return
    # events: own features whose cluster (a) merges with (b) in this step
    f = a = b = link = np.zeros(0, dtype=np.int64)
    bits = np.zeros((0, st.words), dtype=_BITS)
    skip = None
    if merges:
        src, w, lo, hi = _gather(merges, ("w", "lo", "hi"))
        mine = (lo >= robot.gid0) & (lo < robot.gid0 + robot.m)
        f = np.where(mine, lo, hi) - robot.gid0
        mutual = (st.has_best[f] & (st.best_w[f] == w) & (st.best_lo[f] == lo)
                  & (st.best_hi[f] == hi))  # the best of both clusters: locally dominant
        f, far, src = f[mutual], (lo + hi - robot.gid0 - f)[mutual], src[mutual]
        link = robot.find_links(src, far - robot.offsets[src])
        a, b = st.label[f], st.other[link]
        bits = _cams(robot, a) | _cams(robot, b)
    if rels:
        src, g, old, rows = _gather(rels, ("feat", "old", "cams"))
        ok = ~st.relabeled[g]
        g, old, rows, src = g[ok], old[ok], rows[ok], src[ok]
        skip = np.sort(g * robot.n + src)  # every neighbour that sent it holds it
        g, first = np.unique(g, return_index=True)
        f = np.concatenate([f, g])
        a, b = np.concatenate([a, old[first, 0]]), np.concatenate([b, old[first, 1]])
        bits = np.concatenate([bits, _from_wire(st, rows[first])])
    if f.size:
        x, y = np.minimum(a, b), np.maximum(a, b)
        pos = np.full(robot.m, -1, dtype=np.int64)
        pos[f] = np.arange(f.size)
        e = pos[robot.link_r]
        # the flood inside each old cluster goes along its flood links as they were
        k = np.flatnonzero(_flood_mask(robot) & (e >= 0))
        if skip is not None and k.size:
            k = k[~isin_sorted(robot.link_r[k].astype(np.int64) * robot.n + robot.link_nbr[k],
                               skip)]
        if k.size:
            ek = e[k]
            old, wire, feat = (np.stack([x[ek], y[ek]], axis=1).astype(st.ids),
                               _to_wire(st, bits[ek]), robot.link_s[k])
            for j, s in _by_nbr(robot, k):
                send(j, RELABEL, {"feat": feat[s], "old": old[s], "cams": wire[s]})
        # apply: own label, the far ends' labels of the links now inside, camera sets
        st.label[f] = x
        st.relabeled[f] = True
        k = np.flatnonzero(e >= 0)
        ek = e[k]
        inside = robot.link_alive[k] & ((st.other[k] == x[ek]) | (st.other[k] == y[ek]))
        st.other[k[inside]] = x[ek[inside]]
        _keep_cams(st, x, bits)
        st.tree[link] = True
        # the far ends of the open links hear the new cluster
        k = k[st.open[k] & ~inside]
        if k.size:
            ek = e[k]
            feat, label, wire = robot.link_r[k], x[ek].astype(st.ids), _to_wire(st, bits[ek])
            for j, s in _by_nbr(robot, k):
                send(j, EXCHANGE, {"feat": feat[s], "label": label[s], "cams": wire[s]})
    _measure(robot)


def _gather(msgs: list[Message], keys: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    """Sender of every entry and the payload arrays ``keys`` of messages of one kind,
    concatenated (ids as int64)."""
    sizes = [m.payload[keys[0]].shape[0] for m in msgs]
    src = np.repeat(np.array([m.src for m in msgs], dtype=np.int64), sizes)
    out = []
    for key in keys:
        parts = [m.payload[key] for m in msgs]
        arr = parts[0] if len(parts) == 1 else np.concatenate(parts)
        out.append(arr if arr.dtype in (np.float64, np.uint8) else arr.astype(np.int64))
    return (src, *out)


def finish_sync(robot: Robot, round_: int) -> None:
    """Cut every own link whose two ends ended in different clusters; name the tracks."""
    st = robot.sync
    cut = robot.link_alive & (st.label[robot.link_r] != st.other)
    k = np.flatnonzero(cut)
    robot.link_alive[k] = False
    robot.deleted_round[k] = round_
    robot.deleted_case[k] = CASE_SYNC
    # the merge is the rule's one pass: iteration 1 (1-based, as every rule logs its cuts),
    # or the detection's own when the merge follows one
    robot.deleted_iteration[k] = max(robot.iteration, 1)
    has_link = np.zeros(robot.m, dtype=bool)
    has_link[robot.link_r[robot.link_alive]] = True
    robot.component = np.where(has_link, st.label, -1)
    _measure(robot)


# --------------------------------------------------------------------------- simulator driver
