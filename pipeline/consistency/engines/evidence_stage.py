"""The ``evidence`` rule in the simulator: bounded label flooding, the evidence rule's bundles on
the small sets, the ``sync`` merge on the large sets' links — memory that follows the links.

Today's rule in its first form ran the detection of Sec. III (rows of ``X``: memory
``Σ |C|²``) and then flooded every conflictive set's bundles to all its robots (memory
``Σ |C|²`` again). On a dense input one wrong link chains thousands of features into one set
(CMU hotel, 101 frames, complete graph, descriptor-only links: one set of 2626 features) and
both ran out of memory. The stage is now three phases, each ended when nothing is in flight
(the termination wave of a robot alone):

1. **Bounded label flooding** (:mod:`..setlists`): every active feature learns the ``B + 1``
   smallest ids of its set; a set of at most ``B`` features (*small*) is then known to all
   its robots with its whole member list (its row of Sec. III), a larger one is known to be
   *large*. ``B`` is the *bundle budget* (:func:`..setlists.bundle_budget`: by default the
   largest set whose bundles fit :data:`..setlists.SET_BUNDLE_BYTES` at a robot; an option,
   :func:`pipeline.consistency.resolve_conflicts`'s ``bundle_budget``).
2. **The evidence rule on the small conflictive sets** (:mod:`..evidence`: flood the bundles,
   every robot solves the set alike, the Kruskal merge with the geometric test): per set the
   same bundles, the same solution, the same cuts in the same rounds as the rule after the
   rows of Sec. III, since a set's flood and solution depend on that set only. Run only if
   some robot found a conflictive feature (the wave's ``CONFLICT`` bit), and unless the
   caller solves those sets itself (``solve_small_sets=False`` of
   :func:`..driver.resolve_conflicts`: the online stage gathers each set's bundles at one
   robot, :mod:`.online`).
2b. **The small sets solved at their roots** (:mod:`..roots`), when the robots were handed
   ``gather_conflictive`` / ``gather_free`` (:func:`..driver.resolve_conflicts`; the online
   stage's robots): every robot on its own inbox (:func:`.gather.run_roots`), the same cuts
   as phase 2 on the conflictive ones.
3. **The ``sync`` merge on the large sets** (:mod:`..sync`): every robot hides its links that
   are not in a large set (both ends of a link know: the two features share their set) and
   runs the distributed greedy merge on the rest; the greedy merge decomposes over connected
   components of the links, so each large set gets the merge of its own links
   (:func:`.sync_batched.run_sync` on those links alone). The large sets lose only the
   geometric test the bundles allowed (their weights: the ``sync`` rule's, with triangle and
   quadrangle support). The hidden links are shown again afterwards. Run only if some robot
   holds a large feature (a wave bit too).

Interpretations (stated): the three phases run one after the other (a deployment could run
2 and 3 at once: they touch disjoint links); a link cut in phase 2 is logged at its round of
the evidence pass, one cut in phase 3 at the last round of the merge, both with case
``evidence`` (the rule's one case); all logged in iteration 1. Tracks: a non-conflictive small
set is named by its smallest id (phase 1), a solved set's pieces by the smallest id of each
(:func:`..evidence.cut_own_side`), a large set's clusters by the merge's labels (the smallest
id of each cluster) — the names the rows of Sec. III gave.

Result: conflict-free (the small sets by the evidence merge, the large ones by the ``sync``
merge, the non-conflictive small sets untouched). Rounds, messages, bytes and memory per
robot are those of the three phases, counted as each phase counts them.

Engines: :func:`run_evidence_stage` (every robot on its own inbox, phase after phase) and
:func:`run_evidence_stage_batched` (the flood of phase 1 on the stacked link tables,
:func:`run_setlists_batched`, then the batched evidence pass of :mod:`.batched_evidence` and
the batched merge of :mod:`.sync_batched`, each falling back to robot by robot where it does
not apply); same results, rounds, messages, bytes and memory per robot
(``tests/pipeline/consistency/engines/test_batched.py``, ``tests/pipeline/consistency/
test_setlists.py``).

Measured (``bench/multiway.py --frames 50 101 --graphs complete --inputs descriptors
--methods evidence sync --team``): CMU hotel, 101 frames, complete graph, descriptor-only
links (one set of 2626 features, ``B = 152``): F1 1.000 as ``sync``, peak RSS well under
1 GB where the rule after the rows ran out of 6 GB; the README's multi-way table has the
figures of one run.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from pipeline.consistency import evidence
from pipeline.consistency.detection import reset_detection
from pipeline.consistency.engines import batched_evidence
from pipeline.consistency.engines.gather import run_roots
from pipeline.consistency.engines.phases import run_quiet_phase
from pipeline.consistency.engines.sync_batched import run_sync, run_sync_batched
from pipeline.consistency.keys import ranges
from pipeline.consistency.robot import Robot
from pipeline.consistency.setlists import (
    KIND,
    SetListState,
    bundle_budget,
    finish_setlists,
    merge_smallest,
    setlists_step,
    start_setlists,
)
from pipeline.consistency.sync import CASE_SYNC, equip_sync, id_dtype
from pipeline.transport import HEADER_BYTES, Transport
from pipeline.transport.simulated import Network

__all__ = ["run_evidence_stage", "run_evidence_stage_batched", "run_setlists",
           "run_setlists_batched"]

_EMPTY_I = np.zeros(0, dtype=np.int64)
#: entries merged in one piece of a round of the batched flood (bounds its arrays)
CHUNK_ENTRIES = 1 << 21


def run_setlists(robots: list[Robot], network: Transport, budget: int, on_round=None,
                 t0: int = 0) -> int:
    """Phase 1 on every robot (each on its own inbox), ended when nothing is in flight;
    returns its rounds."""
    cap = int(sum(rb.m for rb in robots)) + 2
    t = run_quiet_phase(robots, network, lambda rb, send: start_setlists(rb, 1, send, budget),
                        setlists_step, on_round, t0, cap, "bounded label flooding")
    for rb in robots:
        finish_setlists(rb)
    return t


def run_setlists_batched(robots: list[Robot], network: Transport, budget: int, on_round=None,
                         t0: int = 0) -> int:
    """Phase 1 of all robots evaluated at once, on their link tables stacked: the same lists,
    rounds, messages, bytes, memory and robot state as :func:`run_setlists`.

    A *directed link* ``f → g`` is a row of the sender's table (alive there, ``f`` active)
    whose receiver holds it too (alive, ``g`` active) — what the receiver's
    :func:`..setlists.setlists_step` accepts. Each round, the features with new entries send
    them over their rows (one message per sender-receiver pair: header, ``feat`` and ``deg``
    int32 per feature, ``ids`` at :func:`..setlists` id width); the receivers merge them into
    their lists, keyed ``gid · m_total + id``, keeping the ``B + 1`` smallest per feature, and
    the entries that entered are the next round's sends. A robot's list only grows (an
    eviction is a replacement), so its peak is at its last step (lists at their end, ``X``
    still empty) or at :func:`..setlists.finish_setlists`, both measured here as it would.
    """
    n = len(robots)
    if n == 0:
        return 0
    M = np.int64(robots[0].m_total)
    idb = id_dtype(int(M)).itemsize
    for rb in robots:
        reset_detection(rb, 1)
        rb.stopped = not rb.active.any()
    active = np.concatenate([rb.active for rb in robots])
    # sender rows: (sender robot, own gid, receiver robot, far gid), alive and active there
    src, f, dst, g, ok = [], [], [], [], []
    for rb in robots:
        k = np.flatnonzero(rb.link_alive & rb.active[rb.link_r])
        src.append(np.full(k.size, rb.id, dtype=np.int64))
        f.append(rb.gid0 + rb.link_r[k].astype(np.int64))
        dst.append(rb.link_nbr[k].astype(np.int64))
        g.append(rb.offsets[rb.link_nbr[k]] + rb.link_s[k].astype(np.int64))
    src, f, dst, g = (np.concatenate(x) for x in (src, f, dst, g))
    ok = np.zeros(f.size, dtype=bool)  # the receiver holds the row alive, its end active
    for rb in robots:
        k = np.flatnonzero(dst == rb.id)
        twin = rb.find_links(src[k], f[k] - rb.offsets[src[k]])
        hit = twin >= 0
        good = np.zeros(k.size, dtype=bool)
        good[hit] = rb.link_alive[twin[hit]] & rb.active[rb.link_r[twin[hit]]]
        ok[k] = good
    order = np.lexsort((f, dst, src))  # rows by (sender, receiver): its message
    src, f, dst, g, ok = src[order], f[order], dst[order], g[order], ok[order]
    pair = src * n + dst
    deliver = np.flatnonzero(ok)
    deliver = deliver[np.argsort(g[deliver], kind="stable")]  # accepted rows by receiver
    # lists: keys gid * M + id, sorted; round 0 every active feature holds its own id
    own = np.flatnonzero(active).astype(np.int64)
    key = own * M + own
    new_f, new_id = own, own.copy()
    heard = np.zeros(int(M), dtype=bool)
    stepped = np.full(n, -1, dtype=np.int64)  # last round each robot had mail
    t, messages, nbytes = 0, 0, 0
    while True:
        cnt = np.bincount(new_f, minlength=int(M))
        rows = np.flatnonzero(cnt[f] > 0)
        if rows.size == 0:
            break
        ptr = np.r_[0, np.cumsum(cnt)]
        pr, first = np.unique(pair[rows], return_index=True)
        ids_per = np.add.reduceat(cnt[f[rows]], first)
        messages += int(pr.size)
        nbytes += int((HEADER_BYTES + 8 * np.diff(np.r_[first, rows.size])
                       + idb * ids_per).sum())
        t += 1
        network.end_round()
        if on_round is not None:
            on_round(t0 + t)
        stepped[pr % n] = t
        rows = deliver[cnt[f[deliver]] > 0]  # by receiver feature
        heard[g[rows]] = True
        key, fresh = _merge_lists(key, rows, f, g, cnt, ptr, new_id, M, budget)
        new_f, new_id = fresh // M, fresh % M
    if messages:
        network.count(KIND, messages, nbytes)
    kf, kid = key // M, key % M
    bounds = np.searchsorted(kf, np.r_[[rb.gid0 for rb in robots], M])
    for rb in robots:
        a, b = bounds[rb.id], bounds[rb.id + 1]
        rb.setlists = SetListState(
            budget=int(budget), r=kf[a:b] - rb.gid0, ids=kid[a:b], new_r=_EMPTY_I,
            new_ids=_EMPTY_I, heard=heard[rb.gid0:rb.gid0 + rb.m].copy(),
            large=np.zeros(rb.m, dtype=bool))
        rb.X = sp.csr_matrix((rb.m, rb.m_total), dtype=bool)
        rb.X_new = rb.X
        st = rb.setlists
        own_n = int(np.count_nonzero(rb.active))
        # the start's measure (own ids only), then the last step's (lists at their end)
        start = rb.memory_bytes() + 16 * own_n + 2 * rb.m
        rb.peak_memory_bytes = max(rb.peak_memory_bytes, start)
        if stepped[rb.id] >= 0:
            rb.t_stop = int(t0 + stepped[rb.id])
            rb.peak_memory_bytes = max(rb.peak_memory_bytes, rb.memory_bytes() + st.nbytes())
        finish_setlists(rb)
    return t


def _merge_lists(key, rows, f, g, cnt, ptr, new_id, M, budget: int):
    """Merge the entries delivered over ``rows`` (sorted by receiver feature ``g``) into the
    lists ``key`` (sorted ``gid · M + id``), keeping the ``B + 1`` smallest per feature, in
    pieces of at most :data:`CHUNK_ENTRIES` entries cut between receivers; returns the new
    lists and the keys that entered."""
    size = cnt[f[rows]]
    ends = np.cumsum(size)
    cuts = [0]
    while cuts[-1] < rows.size:
        base = ends[cuts[-1] - 1] if cuts[-1] else 0
        j = int(np.searchsorted(ends, base + CHUNK_ENTRIES, side="right"))
        j = max(j, cuts[-1] + 1)
        while j < rows.size and g[rows[j]] == g[rows[j - 1]]:  # a receiver in one piece
            j += 1
        cuts.append(j)
    pieces, fresh, done = [], [], 0
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        part = rows[a:b]
        lo = int(np.searchsorted(key, g[part[0]] * M))
        hi = int(np.searchsorted(key, (g[part[-1]] + 1) * M))
        recv = np.repeat(g[part], cnt[f[part]])
        got = new_id[ranges(ptr[f[part]], ptr[f[part] + 1])]
        merged, entered = merge_smallest(key[lo:hi], recv * M + got, M, budget + 1)
        fresh.append(entered)
        pieces += [key[done:lo], merged]
        done = hi
    pieces.append(key[done:])
    return np.concatenate(pieces), np.concatenate([*fresh, _EMPTY_I])


def _budget(robots: list[Robot]) -> int:
    """``B``: the one the robots were handed (:class:`..evidence.EvidenceState`), else the
    default of the team's size."""
    given = {getattr(rb.evidence, "bundle_budget", None) for rb in robots}
    if len(given) > 1:
        raise ValueError(f"the robots hold different bundle budgets {sorted(map(str, given))}")
    return bundle_budget(robots[0].n if robots else 0, given.pop() if given else None)


def _solve_small(robots: list[Robot]) -> bool:
    """Phase 2 runs unless the robots leave the small sets to the caller or solve them at
    their roots (all alike, :meth:`..evidence.EvidenceState.floods_small`)."""
    given = {rb.evidence.floods_small() for rb in robots}
    if len(given) > 1:
        raise ValueError("the robots disagree on solving the sets of at most B features")
    return given.pop() if given else True


def _after(on_round, t0: int):
    """The progress report of a phase that starts after ``t0`` rounds of the stage."""
    return None if on_round is None else (lambda t: on_round(t0 + t))


def _stage(robots: list[Robot], network: Transport, on_round, batched: bool) -> dict:
    B = _budget(robots)
    flood = run_setlists_batched if batched and type(network) is Network \
        and not network.faulty else run_setlists
    det = flood(robots, network, B, on_round)
    t = det
    res_sets = 0
    if _solve_small(robots) and any(rb.conflictive.any() for rb in robots):
        shift = _after(on_round, t)
        run = batched_evidence.run_evidence_resolution if batched else \
            evidence.run_evidence_resolution
        res = run(robots, network, on_round=shift)
        t += res["rounds"]
        res_sets = res["conflictive_sets"]
    roots = None
    if any(rb.evidence.gather_conflictive or rb.evidence.gather_free for rb in robots):
        c0 = network.counters()
        roots = run_roots(robots, network, _after(on_round, t))
        c1 = network.counters()
        roots.update(start_round=t, messages=c1["messages"] - c0["messages"],
                     bytes=c1["bytes"] - c0["bytes"])
        t += roots["rounds"]
    large = [rb.setlists.large for rb in robots]
    n_large = len({int(lab) for rb, lg in zip(robots, large, strict=True)
                   for lab in rb.setlists.ids[np.searchsorted(rb.setlists.r,
                                                              np.flatnonzero(lg))].tolist()})
    merge_rounds = 0
    if any(lg.any() for lg in large):
        alive = [rb.link_alive.copy() for rb in robots]
        hidden = [a & ~lg[rb.link_r] for rb, a, lg in zip(robots, alive, large, strict=True)]
        for rb, a, h in zip(robots, alive, hidden, strict=True):
            rb.link_alive = a & ~h
            equip_sync(rb, rb.evidence.link_weight)
        shift = _after(on_round, t)
        res = (run_sync_batched if batched else run_sync)(robots, network, on_round=shift)
        merge_rounds = int(res["rounds"])
        t += merge_rounds
        for rb, a, h in zip(robots, alive, hidden, strict=True):
            rb.deleted_case[a & ~rb.link_alive & (rb.deleted_case == CASE_SYNC)] = \
                evidence.CASE_EVIDENCE
            rb.link_alive = rb.link_alive | h
    for rb in robots:  # each robot's peak over the three phases (each measured as it ran)
        network.note_memory(rb.id, rb.peak_memory_bytes)
    out = dict(rounds=t, detection_rounds=det, conflictive_sets=res_sets,
               large_sets=n_large, bundle_budget=B, merge_rounds=merge_rounds)
    if roots is not None:
        out["roots"] = roots
    return out


def run_evidence_stage(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """The ``evidence`` rule's stage (module docstring), every robot on its own inbox.

    Returns ``rounds`` (all phases), ``detection_rounds`` (phase 1), ``conflictive_sets``
    (small sets solved by the bundles), ``large_sets`` (sets of more than ``B`` features,
    solved by the merge), ``bundle_budget`` (``B``) and ``merge_rounds`` (phase 3)."""
    return _stage(robots, network, on_round, False)


def run_evidence_stage_batched(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """:func:`run_evidence_stage` with its three phases evaluated in batch where the batched
    engines apply (same results, rounds, messages, bytes and memory)."""
    return _stage(robots, network, on_round, True)
