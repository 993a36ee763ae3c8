"""Benchmark: what a global move adds to ``sync`` on the synthetic team (a central reference).

On the team of ``bench/multiway.py --team`` (``n`` cameras on a ring2 graph, 30 landmarks
each, 30 % of the linked pairs swap two matches, qualities drawn independently of whether a
match is right) ``sync`` ends below the truth where two pairs around one camera swapped the
same two landmarks: its greedy merge joins landmark A's stretch of the ring before that
camera to B's stretch after it, and only the ring's closure, far away, refutes it (README,
"Multi-way matching"). This bench measures, **centrally**, how much one kind of global move
repairs, as a reference for a distributed version (none exists: this is no rule of the
pipeline):

*Split and re-merge.* For each input link ``e`` the association separates (its ends in two
clusters ``X`` and ``Y``), cut ``X ∪ Y`` in two along the smallest cut between ``e``'s two
cameras (the cameras holding features of ``X`` or ``Y``, joined by the input links kept
inside ``X`` or inside ``Y``, each of capacity one: ``scipy.sparse.csgraph.maximum_flow``),
so that ``X`` and ``Y`` fall into up to four pieces; then merge the pieces with each other
and with the clusters linked to them, greedily by the number of input links between two
groups, never joining two groups that hold one camera (Def. 2.4). The move is kept if the
input links the association joins grow in number (each link counted once, no descriptor
evidence: here it carries none, as the printed test of :func:`multiway.sync_evidence`
shows), and passes over the separated links repeat until none moves.

Prints one line per team and saves ``runs/bench-team-moves/results.json``.

Usage: ``.venv/bin/python bench/team_moves.py [--n 300 3000] [--seeds 0 1 2 3]``
"""

from __future__ import annotations

import argparse
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

from pipeline.association import AssociationGraph, camera_offsets  # noqa: E402
from pipeline.commands.options import seed_argument  # noqa: E402
from pipeline.consistency import resolve_conflicts  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402


def split_and_remerge(m, links, kept: np.ndarray, passes: int = 10):
    """The moves of the module docstring from ``sync``'s kept links; returns the new kept
    mask (input links whose ends end in one cluster) and the number of moves kept."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, maximum_flow

    n = len(m)
    off = camera_offsets(m)
    a = off[links.cam_i] + links.feat_i
    b = off[links.cam_j] + links.feat_j
    cam = np.repeat(np.arange(n), np.asarray(m))
    lab = AssociationGraph(m, links.subset(kept)).components().astype(np.int64)
    moves = 0
    for _ in range(passes):
        moved = False
        for e in np.flatnonzero(lab[a] != lab[b]).tolist():
            X, Y = int(lab[a[e]]), int(lab[b[e]])
            if X == Y:
                continue  # joined by an earlier move of this pass
            s, t = int(cam[a[e]]), int(cam[b[e]])
            inXY = (lab == X) | (lab == Y)
            near = np.flatnonzero(inXY[a] | inXY[b])  # the links a move can change
            na, nb = a[near], b[near]
            ag = near[inXY[na] & inXY[nb] & (lab[na] == lab[nb])]
            ci, cj = cam[a[ag]], cam[b[ag]]
            C = coo_matrix((np.ones(2 * ag.size, dtype=np.int32),
                            (np.r_[ci, cj], np.r_[cj, ci])), shape=(n, n)).tocsr()
            C.sum_duplicates()
            R = C - maximum_flow(C, s, t).flow
            R.data[R.data < 0] = 0
            R.eliminate_zeros()
            S = np.zeros(n, dtype=bool)
            S[breadth_first_order(R, s, directed=True, return_predecessors=False)] = True
            # the pieces of X and Y, and every cluster linked to them, as groups
            fX, fY = np.flatnonzero(lab == X), np.flatnonzero(lab == Y)
            groups = [fX[S[cam[fX]]], fX[~S[cam[fX]]], fY[S[cam[fY]]], fY[~S[cam[fY]]]]
            others = set(lab[na].tolist()) | set(lab[nb].tolist())
            groups = [g for g in groups if g.size]
            pieces = len(groups)
            groups += [np.flatnonzero(lab == L) for L in sorted(others - {X, Y})]
            gid = np.full(lab.size, -1, dtype=np.int64)
            for k, g in enumerate(groups):
                gid[g] = k
            ga, gb = gid[na], gid[nb]
            before = int(np.sum(lab[na] == lab[nb]))
            count: dict = defaultdict(int)
            for p, q in zip(ga.tolist(), gb.tolist(), strict=True):
                if p != q and min(p, q) < pieces:  # other clusters stay as they are
                    count[(min(p, q), max(p, q))] += 1
            parent = list(range(len(groups)))
            cams = [set(cam[g].tolist()) for g in groups]
            for (p, q), _c in sorted(count.items(), key=lambda kv: (-kv[1], kv[0])):
                rp, rq = _root(parent, p), _root(parent, q)
                if rp != rq and not cams[rp] & cams[rq] and min(rp, rq) < pieces:
                    parent[max(rp, rq)] = min(rp, rq)
                    cams[min(rp, rq)] |= cams[max(rp, rq)]
            roots = np.array([_root(parent, k) for k in range(len(groups))])
            after = int(np.sum(roots[ga] == roots[gb]))
            if after > before:
                base = int(lab.max()) + 1
                for k, g in enumerate(groups):
                    lab[g] = base + roots[k]
                moves += 1
                moved = True
        if not moved:
            break
    return lab[a] == lab[b], moves


def _root(parent: list, x: int) -> int:
    while parent[x] != x:
        x = parent[x]
    return x


@one_line_errors
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, nargs="+", default=[300, 3000])
    p.add_argument("--seeds", type=seed_argument, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--out", default=str(ROOT / "runs" / "bench-team-moves"))
    a = p.parse_args(argv)
    if problem := results_folder_problem(a.out):
        p.error(problem)
    if min(a.n) < 2:
        p.error(f"--n {min(a.n)}: a team has at least 2 cameras")
    load = os.getloadavg()[0]
    records = []
    for n in a.n:
        for seed in a.seeds:
            case = multiway.team_case(n, seed=seed)
            kept = ~resolve_conflicts(case.m, case.edges, case.links, resolution="sync").deleted
            _, check = multiway.sync_evidence(case.m, case.links)
            t = time.perf_counter()
            moved, moves = split_and_remerge(case.m, case.links, kept)
            wall = time.perf_counter() - t
            s0, s1 = case.scores(kept), case.scores(moved)
            rec = dict(cameras=n, seed=seed, sync_f1=s0["f1"], moved_f1=s1["f1"],
                       sync_separated=s0["links_split"], moved_separated=s1["links_split"],
                       truth_separated=int((~case.link_good).sum()),
                       consistent=bool(s1["cycle_consistent"]), moves=moves, wall_s=wall,
                       quality_auc=check.get("auc"), quality_p=check.get("p"))
            records.append(rec)
            print(f"{n} cameras, seed {seed}: sync F1 {s0['f1']:.4f} ({s0['links_split']} input "
                  f"links separated) -> after {moves} move(s) {s1['f1']:.4f} "
                  f"({s1['links_split']}; the truth {rec['truth_separated']}), "
                  f"cycle-consistent {rec['consistent']}, {wall:.1f} s; quality AUC "
                  # none without a link the triangles confirm and one they refute (saved null)
                  + ("-" if rec["quality_auc"] is None else f"{rec['quality_auc']:.3f}"),
                  flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", {"machine": multiway.machine(load), "args": vars(a),
                                             "records": records})
    print(f"saved {out / 'results.json'} (load average {load:.1f} at start, "
          f"{os.getloadavg()[0]:.1f} at end)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
