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
   some robot found a conflictive feature (the wave's ``CONFLICT`` bit).
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

Engines: :func:`run_evidence_stage` (every robot on its own inbox: the evidence pass and
the merge robot by robot) and :func:`run_evidence_stage_batched` (the same label flooding,
then the batched evidence pass of :mod:`.batched_evidence` and the batched merge of
:mod:`.sync_batched`, each falling back to robot by robot where it does not apply); same
results, rounds, messages, bytes and memory (``tests/pipeline/consistency/engines/
test_batched.py``).
"""

from __future__ import annotations

import numpy as np

from pipeline.consistency import evidence
from pipeline.consistency.engines import batched_evidence
from pipeline.consistency.engines.phases import run_quiet_phase
from pipeline.consistency.engines.sync_batched import run_sync, run_sync_batched
from pipeline.consistency.robot import Robot
from pipeline.consistency.setlists import (
    bundle_budget,
    finish_setlists,
    setlists_step,
    start_setlists,
)
from pipeline.consistency.sync import CASE_SYNC, equip_sync
from pipeline.transport import Transport

__all__ = ["run_evidence_stage", "run_evidence_stage_batched", "run_setlists"]


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


def _budget(robots: list[Robot]) -> int:
    """``B``: the one the robots were handed (:class:`..evidence.EvidenceState`), else the
    default of the team's size."""
    given = {getattr(rb.evidence, "bundle_budget", None) for rb in robots}
    if len(given) > 1:
        raise ValueError(f"the robots hold different bundle budgets {sorted(map(str, given))}")
    return bundle_budget(robots[0].n if robots else 0, given.pop() if given else None)


def _stage(robots: list[Robot], network: Transport, on_round, batched: bool) -> dict:
    B = _budget(robots)
    det = run_setlists(robots, network, B, on_round)
    t = det
    res_sets = 0
    if any(rb.conflictive.any() for rb in robots):
        shift = (lambda s: (lambda r: on_round(s + r)))(t) if on_round is not None else None
        run = batched_evidence.run_evidence_resolution if batched else \
            evidence.run_evidence_resolution
        res = run(robots, network, on_round=shift)
        t += res["rounds"]
        res_sets = res["conflictive_sets"]
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
        shift = (lambda s: (lambda r: on_round(s + r)))(t) if on_round is not None else None
        res = (run_sync_batched if batched else run_sync)(robots, network, on_round=shift)
        merge_rounds = int(res["rounds"])
        t += merge_rounds
        for rb, a, h in zip(robots, alive, hidden, strict=True):
            rb.deleted_case[a & ~rb.link_alive & (rb.deleted_case == CASE_SYNC)] = \
                evidence.CASE_EVIDENCE
            rb.link_alive = rb.link_alive | h
    for rb in robots:  # each robot's peak over the three phases (each measured as it ran)
        network.note_memory(rb.id, rb.peak_memory_bytes)
    return dict(rounds=t, detection_rounds=det, conflictive_sets=res_sets,
                large_sets=n_large, bundle_budget=B, merge_rounds=merge_rounds)


def run_evidence_stage(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """The ``evidence`` rule's stage (module docstring), every robot on its own inbox.

    Returns ``rounds`` (all phases), ``detection_rounds`` (phase 1), ``conflictive_sets``
    (small sets solved by the bundles), ``large_sets`` (sets of more than ``B`` features,
    solved by the merge), ``bundle_budget`` (``B``) and ``merge_rounds`` (phase 3)."""
    return _stage(robots, network, on_round, False)


def run_evidence_stage_batched(robots: list[Robot], network: Transport, on_round=None) -> dict:
    """:func:`run_evidence_stage` with phases 2 and 3 evaluated in batch (same results)."""
    return _stage(robots, network, on_round, True)
