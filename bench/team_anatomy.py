"""Benchmark: where ``sync``'s errors on the synthetic ring2 team come from, and two orders tried.

On the team of ``bench/multiway.py --team`` (``n`` cameras on a ring2 graph, 30 landmarks
each, 30 % of the linked pairs swap two matches, qualities drawn independently of whether a
match is right) ``sync`` ends at F1 0.94–0.98 on 3,000 cameras (README, "Multi-way
matching"). This bench takes its merge apart, **centrally**, on the weights its robots
compute (:func:`multiway.sync_evidence`: ``w = λ + TRIANGLE_WEIGHT · s``, ``s`` the cycle
support of :func:`pipeline.consistency.cycles.support_term`):

*Links.* Good and wrong input links with cycle support (``s > 0``: a triangle or a
quadrangle closes over the link) and without.

*Stretches.* On this input every supported link comes before every unsupported one in
``sync``'s order (``s`` is 0, 1 or 2 on ring2 and ``TRIANGLE_WEIGHT`` exceeds the range of
``λ``; each row checks it: ``supported_first``), so the clusters ``sync``'s merge holds once
the supported links are done are those of the supported links alone, merged in its order:
the *stretches*. Counted: how many, how many hold two landmarks, and per landmark into how
many stretches its ring falls.

*Eligible pairs.* Pairs of stretches that share no camera and are joined by unsupported
links: the choices left to the rest of the merge, by whether the two stretches are of one
landmark, and by the number of links between them.

*Orders of the unsupported links* after the stretches (each conflict-free by construction,
Def. 2.4; measured, none adopted), each with its F1 and the input links its association
separates (beside the truth's: the wrong links):

- ``sync``: by ``w`` (here the quality's log-odds, noise), as the rule does; checked equal to
  the rule's own kept links (``same_as_sync``);
- ``contested_last``: a pair of clusters merges before any *contested* one (a cluster that
  has another eligible partner sharing a camera with this one: the two cannot both join it),
  in ``w`` order among each kind; a contested pair is taken only when no other is left;
- ``count_linkage``: pairs of clusters by the number of unsupported links between them
  (merged clusters add their counts), ties by the clusters' smallest ids.

and, as a central reference for a global move (like ``bench/team_moves.py``; no rule of the
pipeline), ``stretch_search`` (kept in ``bench/sync_weights.py``, which runs it on the
other inputs): a local search over whole stretches starting from ``sync``'s
association, counting input links (the quality is noise here). A *Kempe chain* move takes a
stretch ``x`` from its cluster ``G`` into a cluster ``H`` linked to it, the stretches of
``H`` that share a camera with ``x`` into ``G``, the stretches of ``G`` that share a camera
with those into ``H``, and so on until none is left (both clusters stay conflict-free); it
is made when it joins more input links, or as many (a plateau move, each chain at most once
per run, so the search ends). Two clusters linked to each other that share no camera merge.
Passes repeat until nothing moves (at most ``sync_weights.SEARCH_PASSES``).

Prints one line per team and saves ``runs/bench-team-anatomy/results.json``.

Usage: ``.venv/bin/python bench/team_anatomy.py [--n 300 3000] [--seeds 0 1 2 3]``
"""

from __future__ import annotations

import argparse
import heapq
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import multiway  # noqa: E402
import numpy as np  # noqa: E402
from sync_weights import Merge, stretch_search, sync_order  # noqa: E402

from pipeline.association import AssociationGraph  # noqa: E402
from pipeline.commands.options import count_argument, seed_argument  # noqa: E402
from pipeline.consistency import resolve_conflicts  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.matching.link_evidence import ratio_llr  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402


def stretches(m, a, b, w, s) -> tuple[Merge, list[int]]:
    """The merge after the supported links (``s > 0``) in ``sync``'s order, and the
    unsupported links in that order."""
    mg = Merge(m)
    rest = []
    for k in sync_order(a, b, w).tolist():
        if s[k] > 0:
            mg.try_join(a[k], b[k])
        else:
            rest.append(k)
    return mg, rest


def contested_last(mg: Merge, a, b, rest: list[int]) -> None:
    """Merge the unsupported links ``rest`` (in ``sync``'s order), uncontested pairs first
    (module docstring)."""
    open_ = list(rest)
    while True:
        pairs = [(k, mg.root(a[k]), mg.root(b[k])) for k in open_]
        pairs = [(k, x, y) for k, x, y in pairs if mg.eligible(x, y)]
        if not pairs:
            return
        open_ = [k for k, _, _ in pairs]
        partners = defaultdict(set)
        for _, x, y in pairs:
            partners[x].add(y)
            partners[y].add(x)

        def contested(x, y, partners=partners):
            return any(z != y and mg.cameras(z) & mg.cameras(y) for z in partners[x])

        pick = next(((x, y) for _, x, y in pairs
                     if not contested(x, y) and not contested(y, x)), pairs[0][1:])
        mg.join(*pick)


def count_linkage(mg: Merge, a, b, rest: list[int]) -> None:
    """Merge clusters by the number of unsupported links between them (module docstring)."""
    count: dict[int, dict[int, int]] = defaultdict(lambda: defaultdict(int))
    for k in rest:
        x, y = mg.root(a[k]), mg.root(b[k])
        if x != y:
            count[x][y] += 1
            count[y][x] += 1
    heap = [(-c, x, y) for x in count for y, c in count[x].items() if x < y]
    heapq.heapify(heap)
    while heap:
        c, x, y = heapq.heappop(heap)
        if x not in count or count[x].get(y) != -c:
            continue  # stale: a cluster merged since
        if not mg.eligible(x, y):
            del count[x][y], count[y][x]
            continue
        r = mg.join(x, y)
        merged: dict[int, int] = defaultdict(int)
        for old in (x, y):
            for z, cz in count.pop(old).items():
                if z not in (x, y):
                    merged[z] += cz
                    count[z].pop(old)
        count[r] = merged
        for z, cz in merged.items():
            count[z][r] = cz
            heapq.heappush(heap, (-cz, min(r, z), max(r, z)))


def anatomy(case) -> dict:
    """The counts and F1 of the module docstring for one team."""
    m, links = case.m, case.links
    a, b = AssociationGraph(m, links).global_ids()
    truth = np.asarray(case.truth_id)
    w, check = multiway.sync_evidence(m, links)
    lam = ratio_llr(1.0 - links.quality)
    s = w - lam
    good = np.asarray(case.link_good, bool)
    sup = s > 0
    rec = dict(links=dict(good_supported=int((good & sup).sum()),
                          good_unsupported=int((good & ~sup).sum()),
                          wrong_supported=int((~good & sup).sum()),
                          wrong_unsupported=int((~good & ~sup).sum())),
               supported_first=bool(not sup.any() or not (~sup).any()
                                    or w[sup].min() > w[~sup].max()),
               truth_separated=int((~good).sum()), quality_auc=check.get("auc"))
    mg, rest = stretches(m, a, b, w, s)
    roots = np.array([mg.root(f) for f in range(len(truth))])
    _, comp = np.unique(roots, return_inverse=True)
    members = defaultdict(set)
    for c, t in zip(comp.tolist(), truth.tolist(), strict=True):
        members[c].add(t)
    per_landmark = np.bincount(np.array([t for ts in members.values() for t in ts]))
    rec["stretches"] = dict(count=len(members),
                            impure=sum(len(ts) > 1 for ts in members.values()),
                            per_landmark_min=int(per_landmark.min()),
                            per_landmark_median=float(np.median(per_landmark)),
                            per_landmark_max=int(per_landmark.max()))
    between: dict[tuple, int] = defaultdict(int)
    for k in rest:
        x, y = int(comp[a[k]]), int(comp[b[k]])
        if x != y and mg.eligible(int(roots[a[k]]), int(roots[b[k]])):
            between[(min(x, y), max(x, y))] += 1
    eligible: dict[str, int] = defaultdict(int)
    for (x, y), c in between.items():
        kind = "one_landmark" if members[x] == members[y] and len(members[x]) == 1 \
            else "two_landmarks"
        eligible[f"{kind}_{c}_links"] += 1
    rec["eligible_pairs"] = dict(sorted(eligible.items()))
    sync = ~resolve_conflicts(m, case.edges, links, resolution="sync").deleted
    rec["orders"] = {}
    for name, finish in (("sync", None), ("contested_last", contested_last),
                         ("count_linkage", count_linkage)):
        mg, rest = stretches(m, a, b, w, s)
        if finish is None:
            for k in rest:
                mg.try_join(a[k], b[k])
        else:
            finish(mg, a, b, rest)
        kept = mg.kept(a, b)
        sc = case.scores(kept)
        rec["orders"][name] = dict(f1=sc["f1"], cycle_consistent=bool(sc["cycle_consistent"]),
                                   links_separated=int((~kept).sum()))
        if name == "sync":
            rec["same_as_sync"] = bool(np.array_equal(kept, sync))
    t = time.process_time()
    kept = stretch_search(comp, mg.cam, a, b, sync)
    cpu = time.process_time() - t
    sc = case.scores(kept)
    rec["orders"]["stretch_search"] = dict(f1=sc["f1"],
                                           cycle_consistent=bool(sc["cycle_consistent"]),
                                           links_separated=int((~kept).sum()), cpu_s=cpu)
    return rec


@one_line_errors
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=count_argument, nargs="+", default=[300, 3000])
    p.add_argument("--seeds", type=seed_argument, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--out", default=str(ROOT / "runs" / "bench-team-anatomy"))
    a = p.parse_args(argv)
    if problem := results_folder_problem(a.out):
        p.error(problem)
    if min(a.n) < 3:
        p.error(f"--n {min(a.n)}: a ring2 team has at least 3 cameras")
    load = os.getloadavg()[0]
    records = []
    for n in a.n:
        for seed in a.seeds:
            rec = dict(cameras=n, seed=seed, **anatomy(multiway.team_case(n, seed=seed)))
            records.append(rec)
            ln, st, o = rec["links"], rec["stretches"], rec["orders"]
            print(f"{n} cameras, seed {seed}: links without cycle support {ln['good_unsupported']} "
                  f"good / {ln['wrong_unsupported']} wrong (with: {ln['good_supported']} / "
                  f"{ln['wrong_supported']}); {st['count']} stretches ({st['impure']} of two "
                  f"landmarks), {st['per_landmark_min']}-{st['per_landmark_max']} per landmark "
                  f"(median {st['per_landmark_median']:g}); eligible stretch pairs "
                  + ", ".join(f"{k} {v}" for k, v in rec["eligible_pairs"].items())
                  + "; F1 (input links separated) " + ", ".join(
                      f"{k} {v['f1']:.4f} ({v['links_separated']})" for k, v in o.items())
                  + f", the truth ({rec['truth_separated']}); the stretch search took "
                  f"{o['stretch_search']['cpu_s']:.1f} s of CPU"
                  + ("" if rec["same_as_sync"] else " (the sync order differs from the rule!)")
                  + ("" if rec["supported_first"] else " (a supported link comes after an "
                     "unsupported one: the stretches are not sync's state)"), flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", {"machine": multiway.machine(load), "args": vars(a),
                                             "records": records})
    print(f"saved {out / 'results.json'} (load average {load:.1f} at start, "
          f"{os.getloadavg()[0]:.1f} at end)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
