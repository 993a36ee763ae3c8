"""Benchmark: the distributed consistency stage at scale, next to its centralized counterpart.

Random formations of ``n`` robots (default 6 … 1000), about 2000 features each, on a ring with
chords: every robot talks to its ring neighbours, about half also to a robot 2–4 places
ahead, plus ``n // 20`` random long chords. Associations have a realistic track structure: a
landmark is seen by a run of consecutive robots on the ring (run length geometric, mean about
2.2), each robot pair on a comm edge finds a common landmark's link with probability
``--detect`` (missing links), and ``--spurious`` × (links of the edge) spurious links join
random unmatched features (one-to-one kept, Assumption 2.2).

In one run, for each ``n`` and each resolution (``--resolution``: Alg. 1, ``paper``, and the
evidence rule, ``evidence``, the default of the command line): the whole distributed
simulation (:func:`resolve_conflicts`: all robots, all rounds, every message counted) against
centralized union-find detection plus the "drop every link of a conflictive set" baseline on
the same input, run alternately (``--repeat`` times, medians: the ratio survives a busy
machine). The simulation runs with the batched evaluation (the default where it applies,
:mod:`pipeline.consistency.engines.batched`, :mod:`pipeline.consistency.engines.batched_evidence`) and, up to
``--per-robot-max-n``, also robot by robot; both must give the same cuts, rounds, messages and
bytes (checked). Prints a table and saves ``runs/bench-consistency/results.json`` (``records``:
one per ``n`` and resolution; ``meta``: the machine, the load and the command) and ``time_bytes.png`` (time and MB sent against ``n``).

Targets: distributed ≤ 10× union-find at ``n`` = 100 and 1000, ``n`` = 1000 in ≤ 10 s, and
≤ 8 MB sent at ``n`` = 100 (delta messages; bytes as a robot puts them on the wire).

``diameter_bound`` is ``d + 1`` with ``d`` the diameter of the association graph (Cor. 3.6),
computed centrally by breadth-first search within each association set; ``rounds`` is the
total of detection and resolution rounds over all iterations.

Usage: ``.venv/bin/python bench/consistency_scale.py [--quick] [--n 6 10 …] [--per-robot-max-n 200]
[--resolution paper evidence]``
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402
from scipy.sparse.csgraph import connected_components, shortest_path  # noqa: E402

from pipeline.association import AssociationGraph, count_conflicts  # noqa: E402
from pipeline.commands.options import count_argument, given_options, seed_argument  # noqa: E402
from pipeline.consistency import resolve_conflicts  # noqa: E402
from pipeline.consistency.centralized import drop_conflictive_sets, is_conflict_free  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import OutputFiles, write_json_atomic  # noqa: E402
from pipeline.types import Links  # noqa: E402

OUT = ROOT / "runs" / "bench-consistency"
TARGET_RATIO, TARGET_N_RATIO = 10.0, (100, 1000)
TARGET_BIG_N, TARGET_BIG_S = 1000, 10.0
TARGET_MB_N, TARGET_MB = 100, 8.0


def ring_chords(n: int, rng: np.random.Generator) -> np.ndarray:
    """Ring edges, a chord 2–4 ahead from about half of the robots, ``n // 20`` long chords."""
    edges = {(i, (i + 1) % n) for i in range(n)}
    for i in range(n):
        if rng.random() < 0.5:
            edges.add((i, (i + int(rng.integers(2, 5))) % n))
    for _ in range(max(1, n // 20)):
        a, b = rng.choice(n, 2, replace=False)
        edges.add((int(a), int(b)))
    return np.array(sorted({(min(a, b), max(a, b)) for a, b in edges if a != b}), dtype=np.int64)


def synthetic_formation(n: int, features: int, seed: int, spurious: float, detect: float):
    """Features per camera ``(n,)``, comm edges ``(E, 2)``, links and their truth ``(L,)``."""
    rng = np.random.default_rng(seed)
    edges = ring_chords(n, rng)
    # landmarks seen by runs of consecutive robots on the ring
    lengths = np.minimum(rng.geometric(0.45, size=int(features * n / 1.8)), max(1, n // 2))
    starts = rng.integers(0, n, size=lengths.size)
    cams = np.concatenate([(starts[lengths > k] + k) % n for k in range(int(lengths.max()))])
    lms = np.concatenate([np.flatnonzero(lengths > k) for k in range(int(lengths.max()))])
    order = rng.permutation(cams.size)
    cams, lms = cams[order], lms[order]
    order = np.argsort(cams, kind="stable")
    cams, lms = cams[order], lms[order]
    local = np.arange(cams.size) - np.searchsorted(cams, np.arange(n))[cams]  # shuffled ids
    keep = local < features
    cams, lms, local = cams[keep], lms[keep], local[keep]
    fpc = np.bincount(cams, minlength=n)
    key = lms * n + cams
    ko = np.argsort(key)
    key_s, loc_s = key[ko], local[ko]
    cam_start = np.searchsorted(cams, np.arange(n + 1))
    parts = []
    for a, b in edges:
        sl = slice(cam_start[a], cam_start[a + 1])
        kb = lms[sl] * n + b
        pos = np.minimum(np.searchsorted(key_s, kb), key_s.size - 1)
        hit = key_s[pos] == kb
        r, s = local[sl][hit], loc_s[pos[hit]]
        found = rng.random(r.size) < detect
        r, s = r[found], s[found]
        free_a = np.setdiff1d(np.arange(fpc[a]), r)
        free_b = np.setdiff1d(np.arange(fpc[b]), s)
        k = min(int(round(spurious * max(r.size, 0.02 * min(fpc[a], fpc[b])))), free_a.size,
                free_b.size)
        sr = rng.choice(free_a, k, replace=False)
        ss = rng.choice(free_b, k, replace=False)
        parts.append((np.full(r.size + k, a), np.r_[r, sr], np.full(r.size + k, b), np.r_[s, ss],
                      np.r_[rng.uniform(0.3, 1.0, r.size), rng.uniform(0.0, 0.7, k)],
                      np.r_[np.ones(r.size, bool), np.zeros(k, bool)]))
    cols = [np.concatenate([p[c] for p in parts]) for c in range(6)]
    return fpc, edges, Links(*cols[:5]), cols[5]


def association_diameter(fpc, links: Links, batch_nodes: int = 3000) -> int:
    """Diameter ``d`` of the association graph: BFS within each association set, sets batched."""
    A = AssociationGraph(fpc, links).adjacency().tocsr()
    _, labels = connected_components(A, directed=False)
    sizes = np.bincount(labels)
    in_set = np.flatnonzero(sizes[labels] >= 2)
    if in_set.size == 0:
        return 0
    in_set = in_set[np.argsort(labels[in_set], kind="stable")]
    bounds = np.flatnonzero(np.r_[True, labels[in_set][1:] != labels[in_set][:-1], True])
    d, start = 0, 0
    while start < bounds.size - 1:
        stop = start + 1
        while stop < bounds.size - 1 and bounds[stop + 1] - bounds[start] <= batch_nodes:
            stop += 1
        nodes = in_set[bounds[start]:bounds[stop]]
        D = shortest_path(A[nodes][:, nodes], unweighted=True, directed=False)
        d = max(d, int(D[np.isfinite(D)].max()))
        start = stop
    return d


def bench_one(n: int, resolution: str, formation: tuple, args) -> dict:
    fpc, edges, links, truth = formation
    before = count_conflicts(AssociationGraph(fpc, links))

    # the distributed stage and the centralized baseline alternately, medians of --repeat runs
    dist_t, cent_t = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        # batched where it applies (here: always)
        res = resolve_conflicts(fpc, edges, links, resolution=resolution)
        dist_t.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        kept_drop = drop_conflictive_sets(fpc, links)  # union-find detection + drop-the-set
        cent_t.append(time.perf_counter() - t0)
    distributed_s, centralized_s = float(np.median(dist_t)), float(np.median(cent_t))
    per_robot_s = None
    if n <= args.per_robot_max_n:
        t0 = time.perf_counter()
        one_by_one = resolve_conflicts(fpc, edges, links, resolution=resolution,
                                       engine="per-robot")
        per_robot_s = time.perf_counter() - t0
        assert np.array_equal(one_by_one.deleted, res.deleted)
        assert np.array_equal(one_by_one.round, res.round)
        for k in ("messages", "bytes", "detection_rounds", "resolution_rounds",
                  "max_robot_memory_bytes"):
            assert one_by_one.stats[k] == res.stats[k], k


    assert is_conflict_free(fpc, res.kept()) and is_conflict_free(fpc, links.subset(kept_drop))
    d = association_diameter(fpc, links)
    st = res.stats
    it = st["per_iteration"]
    rec = dict(
        n=n, resolution=resolution, comm_edges=int(len(edges)), features=int(fpc.sum()), m_sum=before.m_sum,
        links=len(links), spurious_links=int((~truth).sum()),
        conflictive_sets=before.conflictive_sets, conflictive_features=before.conflictive_features,
        distributed_s=round(distributed_s, 4), centralized_s=round(centralized_s, 4),
        ratio=round(distributed_s / max(centralized_s, 1e-9), 1),
        per_robot_s=None if per_robot_s is None else round(per_robot_s, 4),
        per_robot_ratio=None if per_robot_s is None else
        round(per_robot_s / max(centralized_s, 1e-9), 1),
        iterations=st["iterations"],
        rounds=st["detection_rounds"] + st["resolution_rounds"],
        detection_rounds=st["detection_rounds"], resolution_rounds=st["resolution_rounds"],
        first_detection_rounds=int(it[0]["detection_rounds"]), diameter=d, diameter_bound=d + 1,
        max_resolution_rounds=int(max(p["resolution_rounds"] for p in it)), resolution_bound=n + 1,
        messages=st["messages"], bytes=st["bytes"], bytes_by_kind=st["bytes_by_kind"],
        max_robot_memory_bytes=st["max_robot_memory_bytes"],
        distributed=dict(deleted=int(res.deleted.sum()),
                         good_deleted=int((res.deleted & truth).sum()),
                         spurious_deleted=int((res.deleted & ~truth).sum())),
        drop_set=dict(deleted=int((~kept_drop).sum()), good_deleted=int((~kept_drop & truth).sum()),
                      spurious_deleted=int((~kept_drop & ~truth).sum())),
    )
    return rec


def plot(records: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    resolutions = list(dict.fromkeys(r["resolution"] for r in records))
    for k, resolution in enumerate(resolutions):
        rs = [r for r in records if r["resolution"] == resolution]
        a1.plot([r["n"] for r in rs], [r["distributed_s"] for r in rs], "o-", color=f"C{k}",
                label=f"distributed ({resolution}), batched evaluation")
        pr = [(r["n"], r["per_robot_s"]) for r in rs if r["per_robot_s"] is not None]
        if pr:
            a1.plot(*zip(*pr, strict=True), "^--", color=f"C{k}",
                    label=f"distributed ({resolution}), robot by robot")
    base = [r for r in records if r["resolution"] == resolutions[0]]
    n = [r["n"] for r in base]
    a1.plot(n, [r["centralized_s"] for r in base], "s-", color="k",
            label="centralized union-find + drop set")
    a1.plot(n, [TARGET_RATIO * r["centralized_s"] for r in base], ":", color="gray",
            label=f"{TARGET_RATIO:.0f}x union-find")
    a1.set_xlabel("robots n")
    a1.set_ylabel("wall time [s]")
    a1.set_xscale("log")
    a1.set_yscale("log")
    a1.legend(fontsize=8)
    b = a2.twinx()
    for k, resolution in enumerate(resolutions):
        rs = [r for r in records if r["resolution"] == resolution]
        a2.plot([r["n"] for r in rs], [r["bytes"] / 1e6 for r in rs], "o-", color=f"C{k}",
                label=f"MB sent ({resolution})")
        b.plot([r["n"] for r in rs], [r["messages"] for r in rs], "s:", color=f"C{k}",
               label=f"messages ({resolution})")
    a2.set_xlabel("robots n")
    a2.set_ylabel("MB sent (delta detection messages)")
    a2.set_xscale("log")
    a2.set_yscale("log")
    b.set_ylabel("messages")
    b.set_yscale("log")
    a2.legend(loc="upper left", fontsize=8)
    b.legend(loc="lower right", fontsize=8)
    fig.suptitle("Distributed consistency stage (Aragüés et al.) vs centralized")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[6, 10, 20, 50, 100, 200, 500, 1000])
    ap.add_argument("--repeat", type=count_argument, default=3,
                    help="alternating runs of the distributed stage and union-find (medians)")
    ap.add_argument("--per-robot-max-n", type=int, default=200,
                    help="also run robot by robot (the engine of faults and middleware) up to this n")
    ap.add_argument("--resolution", nargs="+", choices=("paper", "evidence"),
                    default=["paper", "evidence"], help="resolutions to run, side by side")
    ap.add_argument("--quick", action="store_true", help="small n only (6, 10, 20), unless --n is given")
    ap.add_argument("--features", type=int, default=2000, help="features per robot")
    ap.add_argument("--spurious", type=float, default=0.03,
                    help="spurious links per edge, as a fraction of its true links")
    ap.add_argument("--detect", type=float, default=0.85, help="probability a true link is found")
    ap.add_argument("--seed", type=seed_argument, default=0)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    ns = [6, 10, 20] if args.quick and "n" not in given_options(ap, argv) else args.n
    if min(ns) < 2:
        ap.error(f"--n {min(ns)}: a team has at least 2 robots")
    if importlib.util.find_spec("matplotlib") is None:
        # checked before the runs: the figure is drawn at the end, after minutes of work
        ap.error("matplotlib is missing, for the figure time_bytes.png: install the bench "
                 "extra (make bench, or pip install -e '.[bench]')")

    header = (f"{'n':>5} {'resolution':>10} {'m_sum':>8} {'links':>7} {'confl':>5} {'dist_s':>7} {'robot_s':>7} "
              f"{'uf_s':>6} {'ratio':>5} {'r_ratio':>7} {'it':>2} {'det1':>4} {'d+1':>4} "
              f"{'res':>4} {'n+1':>5} {'rounds':>6} {'messages':>9} {'MB':>7} "
              f"{'mem/robot KB':>12} {'cut dist/drop':>14}")
    print(header)
    records = []
    for n in ns:
        formation = synthetic_formation(n, args.features, args.seed + n, args.spurious,
                                        args.detect)
        for resolution in args.resolution:
            r = bench_one(n, resolution, formation, args)
            records.append(r)
            _print_row(r)
    _print_targets(records)
    args.out.mkdir(parents=True, exist_ok=True)
    meta = dict(python=platform.python_version(), machine=platform.machine(), repeat=args.repeat,
                features_per_robot=args.features, spurious=args.spurious, detect=args.detect,
                seed=args.seed, load_average=os.getloadavg(), command=" ".join(sys.argv))
    # the figures, what they were measured on and their plot are replaced together: a Ctrl-C
    # while the plot was drawn left a new results.json beside a half-written time_bytes.png
    with OutputFiles(replace=True) as files:
        write_json_atomic(files.path(args.out / "results.json", "--out"),
                          dict(meta=meta, records=records))
        plot(records, files.path(args.out / "time_bytes.png", "--out"))
    print(f"saved {args.out / 'results.json'} and {args.out / 'time_bytes.png'}")
    return 0


def _print_row(r: dict) -> None:
    robot_s = "-" if r["per_robot_s"] is None else f"{r['per_robot_s']:.2f}"
    r_ratio = "-" if r["per_robot_ratio"] is None else f"{r['per_robot_ratio']:.0f}"
    print(f"{r['n']:>5} {r['resolution']:>10} {r['m_sum']:>8} {r['links']:>7} "
          f"{r['conflictive_sets']:>5} "
          f"{r['distributed_s']:>7.2f} {robot_s:>7} {r['centralized_s']:>6.3f} "
          f"{r['ratio']:>5.1f} {r_ratio:>7} {r['iterations']:>2} "
          f"{r['first_detection_rounds']:>4} {r['diameter_bound']:>4} "
          f"{r['max_resolution_rounds']:>4} {r['resolution_bound']:>5} {r['rounds']:>6} "
          f"{r['messages']:>9} {r['bytes'] / 1e6:>7.2f} "
          f"{r['max_robot_memory_bytes'] / 1e3:>12.1f} "
          f"{r['distributed']['deleted']:>6}/{r['drop_set']['deleted']:<7}", flush=True)


def _print_targets(records: list[dict]) -> None:
    for resolution in dict.fromkeys(r["resolution"] for r in records):
        by_n = {r["n"]: r for r in records if r["resolution"] == resolution}
        for tn in TARGET_N_RATIO:
            if tn in by_n:
                x = by_n[tn]["ratio"]
                print(f"target ({resolution}): n={tn} distributed {by_n[tn]['distributed_s']:.2f} s"
                      f" = {x:.1f}x union-find ({'within' if x <= TARGET_RATIO else 'OVER'} "
                      f"{TARGET_RATIO:.0f}x)")
        if TARGET_BIG_N in by_n:
            t = by_n[TARGET_BIG_N]["distributed_s"]
            print(f"target ({resolution}): n={TARGET_BIG_N} distributed {t:.2f} s "
                  f"({'within' if t <= TARGET_BIG_S else 'OVER'} {TARGET_BIG_S:.0f} s)")
        if TARGET_MB_N in by_n:
            mb = by_n[TARGET_MB_N]["bytes"] / 1e6
            print(f"target ({resolution}): n={TARGET_MB_N} sent {mb:.2f} MB "
                  f"({'within' if mb <= TARGET_MB else 'OVER'} {TARGET_MB:.0f} MB)")


if __name__ == "__main__":
    sys.exit(main())
