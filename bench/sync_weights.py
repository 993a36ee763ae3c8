"""Benchmark: how much the cycles' support should weigh against the descriptor evidence in ``sync``.

``sync`` (:mod:`pipeline.consistency.sync`) merges by ``w = λ + TRIANGLE_WEIGHT · s``: ``λ``
the link's ratio log-odds, ``s`` its support term (triangles, the agreement rate beyond
``K`` shared views, a quadrangle: :func:`pipeline.consistency.cycles.support_term`). On
the warped hotel sets with hidden landmarks the plain greedy merge by descriptor quality
beats it (README, "Multi-way matching"); on the synthetic ring2 team, where the quality is
noise, the quality merge fails. This bench measures, on the same inputs as
``bench/multiway.py``, the association of the same merge with the support scaled by ``α``:

    ``w_α = λ + α · TRIANGLE_WEIGHT · s``  (``α = 1``: ``sync``; ``α = 0``: the quality order)

computed centrally: each link's ``λ`` and ``w`` are the ``sync`` robots' own (their support
round on the simulator, :func:`multiway.sync_evidence`), ``s = (w − λ) / TRIANGLE_WEIGHT``,
then the sequential constrained greedy merge in ``sync``'s order (``w_α`` decreasing, ties
by :func:`pipeline.consistency.keys.tie_key` and the ids), which ``sync``'s Borůvka rounds
reach exactly (``tests/pipeline/consistency/test_sync.py``); at ``α = 1`` each row checks
its kept links against ``sync``'s own (``same_as_sync``). ``good_links`` (the input's good
links, nothing invented) bounds every rule that only keeps or cuts. Columns: pairwise F1 of
the closure (as CLEAR's), per ``α``, and the spurious links each association keeps.

*Does counting links point at the truth?* On the ring2 team the truth separates fewer input
links than ``sync``'s association, and a global search over whole stretches that counts
links (:func:`stretch_search`, described in ``bench/team_anatomy.py``, started from ``sync``'s association)
raises the F1 there. Each row also gives, for the same input, the input links separated
(ends in two clusters of the closure) by the truth (its wrong links), by ``sync``'s
association and by that search's, the search's F1, and the sum of ``sync``'s own weights
``w`` over the links the truth and ``sync`` join (the objective its merge climbs). Where the
truth separates more links than ``sync``, a move that joins more links leads away from it.

Inputs: CMU hotel (``--frames``, given descriptors only, the Hungarian matches), warped
copies with and without hidden landmarks (:func:`multiway.warped_landmarks`, SIFT,
descriptors only), graphs ``complete``, ``seq:4``, ``ring2``, and the ring2 team
(``--team``, ``--team-seeds``).

Prints one line per input and saves ``runs/bench-sync-weights/results.json``.

Usage: ``.venv/bin/python bench/sync_weights.py [--frames 20 101] [--warped-seeds 1 2 3]
[--team 300] [--alphas 0 0.25 0.5 1 2]``
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import multiway  # noqa: E402
import numpy as np  # noqa: E402
from scipy.sparse import coo_matrix  # noqa: E402
from scipy.sparse.csgraph import connected_components  # noqa: E402

from pipeline.association import AssociationGraph  # noqa: E402
from pipeline.commands.options import seed_argument  # noqa: E402
from pipeline.consistency import resolve_conflicts  # noqa: E402
from pipeline.consistency.evidence import TRIANGLE_WEIGHT  # noqa: E402
from pipeline.consistency.keys import tie_key  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.matching.link_evidence import ratio_llr  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402


class Merge:
    """Clusters of features under the constrained merge (no cluster holds two features of
    one camera, Def. 2.4): a disjoint-set forest with each root's camera set."""

    def __init__(self, m):
        from scipy.cluster.hierarchy import DisjointSet

        self.cam = np.repeat(np.arange(len(m)), np.asarray(m))
        self.ds = DisjointSet(range(int(np.sum(m))))
        self.cams: dict[int, set] = {}

    def root(self, f: int) -> int:
        return self.ds[int(f)]

    def cameras(self, r: int) -> set:
        return self.cams.get(r) or {int(self.cam[r])}  # a singleton's root is its feature

    def eligible(self, x: int, y: int) -> bool:
        return x != y and not self.cameras(x) & self.cameras(y)

    def join(self, x: int, y: int) -> int:
        cx, cy = self.cameras(x), self.cameras(y)
        self.ds.merge(x, y)
        r = self.ds[x]
        self.cams[r] = cx | cy
        return r

    def try_join(self, f: int, g: int) -> None:
        x, y = self.root(f), self.root(g)
        if self.eligible(x, y):
            self.join(x, y)

    def kept(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.array([self.ds.connected(int(p), int(q)) for p, q in zip(a, b, strict=True)])


def sync_order(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Link indices in ``sync``'s order: ``w`` decreasing, ties by :func:`tie_key` of the
    global ends, then the smaller and the larger end."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return np.lexsort((hi, lo, tie_key(lo, hi), -np.asarray(w, np.float64)))


def greedy_merge(m, links, w: np.ndarray) -> np.ndarray:
    """Kept mask of the sequential constrained greedy merge in ``sync``'s order
    (:func:`sync_order`): a link joins its two clusters unless they share a camera (Def.
    2.4); kept iff its ends end in one cluster."""
    a, b = AssociationGraph(m, links).global_ids()
    mg = Merge(m)
    for k in sync_order(a, b, w).tolist():
        mg.try_join(a[k], b[k])
    return mg.kept(a, b)


#: passes of ``stretch_search`` at most
SEARCH_PASSES = 50


def stretch_search(stretch: np.ndarray, cam: np.ndarray, a: np.ndarray, b: np.ndarray,
                   kept: np.ndarray, passes: int = SEARCH_PASSES) -> np.ndarray:
    """The local search of ``bench/team_anatomy.py``'s docstring: ``stretch`` the stretch of each feature,
    ``cam`` its camera, ``a``/``b`` the links' global ends, ``kept`` the association it starts
    from (whose clusters are unions of stretches). Returns the kept mask it ends at; with
    ``passes=0`` the one it starts from (``kept`` itself when its clusters are unions of
    stretches)."""
    n_str, n_cam = int(stretch.max()) + 1, int(cam.max()) + 1
    x, y = stretch[a], stretch[b]
    _, comp = connected_components(coo_matrix((np.ones(int(kept.sum())), (x[kept], y[kept])),
                                              shape=(n_str, n_str)), directed=False)
    group = comp.astype(np.int64)
    C = np.zeros((n_str, n_cam), np.float32)
    C[stretch, cam] = 1.0
    overlap = (C @ C.T) > 0
    np.fill_diagonal(overlap, False)
    W = np.zeros((n_str, n_str), np.int64)
    np.add.at(W, (x, y), 1)
    np.add.at(W, (y, x), 1)
    np.fill_diagonal(W, 0)
    seen: set = set()
    for _ in range(passes):
        moved = False
        for s0 in range(n_str):
            g1 = group[s0]
            for g2 in sorted(set(group[W[s0] > 0].tolist()) - {g1}):
                s1 = np.zeros(n_str, bool)
                s1[s0] = True
                s2 = np.zeros(n_str, bool)
                front = s1.copy()
                while front.any():
                    new2 = (group == g2) & ~s2 & overlap[front].any(0)
                    s2 |= new2
                    front = (group == g1) & ~s1 & overlap[new2].any(0)
                    s1 |= front
                r1, r2 = (group == g1) & ~s1, (group == g2) & ~s2
                gain = (W[np.ix_(s1, r2)].sum() + W[np.ix_(s2, r1)].sum()
                        - W[np.ix_(s1, r1)].sum() - W[np.ix_(s2, r2)].sum())
                key = frozenset((tuple(np.flatnonzero(s1)), tuple(np.flatnonzero(s2))))
                if gain > 0 or (gain == 0 and s2.any() and key not in seen):
                    seen.add(key)
                    group[s1], group[s2] = g2, g1
                    moved = True
                    break
        for g1 in np.unique(group).tolist():
            for g2 in np.unique(group[W[group == g1].sum(0) > 0]).tolist():
                if g2 != g1 and (group == g1).any() and \
                        not (C[group == g1].any(0) & C[group == g2].any(0)).any():
                    group[group == g2] = g1
                    moved = True
        if not moved:
            break
    return group[x] == group[y]


def measure(case, alphas) -> dict:
    """F1 and spurious links kept per ``α`` (module docstring), ``good_links``' F1, and
    whether ``α = 1`` keeps exactly ``sync``'s links."""
    w, _ = multiway.sync_evidence(case.m, case.links)
    lam = ratio_llr(1.0 - case.links.quality)
    support = w - lam  # TRIANGLE_WEIGHT times the support term, as the robots computed it
    good = np.asarray(case.link_good, bool)
    out = {"links": int(len(good)), "good": int(good.sum()), "alphas": {}}
    for alpha in alphas:
        kept = greedy_merge(case.m, case.links, lam + alpha * support)
        out["alphas"][f"{alpha:g}"] = dict(f1=case.scores(kept)["f1"],
                                           spurious_kept=int((kept & ~good).sum()))
        if alpha == 1:
            sync = ~resolve_conflicts(case.m, case.edges, case.links, resolution="sync").deleted
            out["same_as_sync"] = bool(np.array_equal(kept, sync))
    out["good_links_f1"] = case.scores(good)["f1"]
    out["objective"] = objective_check(case, w, lam)
    return out


def objective_check(case, w: np.ndarray, lam: np.ndarray) -> dict:
    """Input links separated by the truth, ``sync`` and the stretch search from ``sync``;
    the search's F1; ``w`` summed over the links the truth and ``sync`` join (module
    docstring).

    The search moves whole *atoms*: the components of the supported links (``w > λ``) that
    ``sync`` kept. ``sync``'s clusters are unions of them, so the search starts exactly from
    ``sync``'s association (``start_is_sync``). The stretches of ``bench/team_anatomy.py``
    (the supported links merged alone) are the same where every supported link precedes
    every other in ``sync``'s order, as on the team; on the warped inputs a strong
    unsupported link can come first and block a supported one, and a stretch would then
    join links ``sync`` cut (the search would start from another association)."""
    m, links = case.m, case.links
    graph = AssociationGraph(m, links)
    a, b = graph.global_ids()
    n = graph.m_total
    cam = np.repeat(np.arange(len(m)), m)
    sync = greedy_merge(m, links, w)
    inner = sync & (w - lam > 0)
    _, atom = connected_components(coo_matrix((np.ones(int(inner.sum())), (a[inner], b[inner])),
                                              shape=(n, n)), directed=False)
    start = stretch_search(atom, cam, a, b, sync, passes=0)
    searched = stretch_search(atom, cam, a, b, sync)
    good = np.asarray(case.link_good, bool)
    return dict(separated=dict(truth=int((~good).sum()), sync=int((~sync).sum()),
                               stretch_search=int((~searched).sum())),
                start_is_sync=bool(np.array_equal(start, sync)),
                stretch_search_f1=case.scores(searched)["f1"],
                w_joined=dict(truth=float(w[good].sum()), sync=float(w[sync].sum())))


def cases(a):
    """(title, record fields, case) of every input of the bench."""
    for frames in a.frames:
        for graph in a.graphs:
            yield (f"hotel {frames} frames, {graph}", dict(data="hotel", frames=frames, graph=graph),
                   multiway.landmark_case(a.data, frames, graph, "descriptors", a.shuffle_seed))
    for hide in a.warped_hide:
        for wseed in a.warped_seeds:
            with tempfile.TemporaryDirectory() as tmp:
                wdir = multiway.warped_landmarks(a.data, Path(tmp) / "w", wseed, hide=hide)
                for graph in a.graphs:
                    yield (f"warped seed {wseed}, hidden {hide:g}, {graph}",
                           dict(data="warped", warp_seed=wseed, hidden=hide, graph=graph),
                           multiway.landmark_case(str(wdir), None, graph, "descriptors",
                                                  a.shuffle_seed, descriptors="sift"))
    for n in a.team:
        for seed in a.team_seeds:
            yield (f"team {n}, seed {seed}", dict(data="team", cameras=n, team_seed=seed,
                                                  graph="ring2"),
                   multiway.team_case(n, seed=seed))


@one_line_errors
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default=str(multiway.SHARED_DATA / "cmu_hotel"))
    p.add_argument("--frames", type=int, nargs="*", default=[20, 101])
    p.add_argument("--graphs", nargs="+", default=["complete", "seq:4", "ring2"])
    p.add_argument("--warped-seeds", type=seed_argument, nargs="*", default=[1, 2, 3])
    p.add_argument("--warped-hide", type=float, nargs="*", default=[0.0, 0.25])
    p.add_argument("--team", type=int, nargs="*", default=[300])
    p.add_argument("--team-seeds", type=seed_argument, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--alphas", type=float, nargs="+", default=[0.0, 0.25, 0.5, 1.0, 2.0])
    p.add_argument("--shuffle-seed", type=seed_argument, default=0)
    p.add_argument("--out", default=str(ROOT / "runs" / "bench-sync-weights"))
    a = p.parse_args(argv)
    if problem := results_folder_problem(a.out):
        p.error(problem)
    if bad := [x for x in a.alphas if not np.isfinite(x) or x < 0]:
        p.error(f"--alphas {bad[0]:g}: a scale of the support is finite and at least 0")
    if a.team and min(a.team) < 3:
        p.error(f"--team {min(a.team)}: a ring2 team has at least 3 cameras")
    if (a.frames or a.warped_seeds) and not Path(a.data).is_dir():
        p.error(f"--data {a.data}: no such folder (a labelled set laid out as CMU hotel); "
                "pass --frames --warped-seeds with no values to run the team rows only")
    if a.frames or a.warped_seeds:
        multiway.check_data_frames(a.data, a.frames, bool(a.warped_seeds and a.warped_hide))
    alphas = sorted(set(a.alphas) | {1.0})
    load = os.getloadavg()[0]
    print("F1 per alpha (w = lambda + alpha * TRIANGLE_WEIGHT * support; 1 = sync, 0 = the "
          "quality order); spurious links kept in brackets")
    print(f"{'input':<38}" + "".join(f"{f'a={x:g}':>15}" for x in alphas) + f"{'good_links':>12}"
          + "   input links separated by truth / sync / stretch search (its F1); sum of w "
          "joined by truth / sync")
    records = []
    for title, fields, case in cases(a):
        r = measure(case, alphas)
        records.append({**fields, **r})
        cells = "".join(f"{r['alphas'][f'{x:g}']['f1']:>8.3f} ({r['alphas'][f'{x:g}']['spurious_kept']:>4})"
                        for x in alphas)
        o = r["objective"]
        same = ("" if r["same_as_sync"] else "  (alpha 1 differs from sync's own links!)") + \
            ("" if o["start_is_sync"] else "  (the search's start differs from sync!)")
        sep, wj = o["separated"], o["w_joined"]
        print(f"{title:<38}{cells}{r['good_links_f1']:>12.3f}   {sep['truth']} / {sep['sync']} / "
              f"{sep['stretch_search']} ({o['stretch_search_f1']:.3f}); {wj['truth']:.0f} / "
              f"{wj['sync']:.0f}{same}", flush=True)
    best = {f"{x:g}": 0 for x in alphas}
    for r in records:
        top = max(v["f1"] for v in r["alphas"].values())
        for k, v in r["alphas"].items():
            best[k] += v["f1"] >= top - 1e-12
    print("inputs on which each alpha is (one of) the best: "
          + ", ".join(f"{k}: {v} of {len(records)}" for k, v in best.items()))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", {"machine": multiway.machine(load), "args": vars(a),
                                             "triangle_weight": TRIANGLE_WEIGHT,
                                             "best_counts": best, "records": records})
    print(f"saved {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
