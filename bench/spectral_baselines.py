"""Benchmark: the centralized spectral baselines (pipeline.consistency.spectral) on CMU hotel.

Input: the landmarks of 20 (stride 5) or all 101 frames, every frame's landmarks in a random
order (``--seed``; the files list them in ground-truth order, so an order-dependent tie-break
would otherwise read the answer), descriptors ``given`` (shape contexts, χ²) or ``sift``;
links = the ungated Hungarian matches of every communication edge (``geometry="none"``,
``ratio=None``: the input CLEAR is benchmarked on). Graphs: complete, ``seq:4``, ``ring2``.

Methods: ``spectral_sync`` and ``clear_sync`` with the universe size estimated (the defaults)
and given (``--universe``, 30), and ``spectral_sync`` with it given and every assignment kept
(``min_cosine=-1``: Pachauri et al. as published). Scores: pairwise precision / recall / F1 of the pairs of features sharing a
label against the true pairs (CLEAR's score); ``input`` = the closure of the links. Time: wall
and CPU of the call; memory: peak of the call's traced allocations (``tracemalloc``: every
NumPy / SciPy array, not the BLAS / ARPACK workspaces) and the process's peak RSS at the end.

Usage: ``.venv/bin/python bench/spectral_baselines.py [--data DIR] [--frames 20 101]
[--graphs complete seq:4 ring2] [--descriptors given sift] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402
from multiway import SHARED_DATA  # noqa: E402

from pipeline.commands.options import count_argument, seed_argument  # noqa: E402
from pipeline.commgraph import comm_graph  # noqa: E402
from pipeline.consistency.spectral import clear_sync, spectral_sync  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.evaluation.metrics import PairwiseTruth, pairwise_scores  # noqa: E402
from pipeline.inputs.landmarks import DESCRIPTOR_SOURCES, load_landmark_folder  # noqa: E402
from pipeline.matching.landmarks import match_landmark_edges  # noqa: E402
from pipeline.outputs import check_output_files  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402


def label_pairs(labels: np.ndarray) -> np.ndarray:
    """Every pair of features sharing a label ``>= 0``: ``(P, 2)``."""
    ids = np.flatnonzero(labels >= 0)
    order = ids[np.argsort(labels[ids], kind="stable")]
    cuts = np.flatnonzero(np.diff(labels[order])) + 1
    parts = []
    for grp in np.split(order, cuts):
        if grp.size > 1:
            a, b = np.triu_indices(grp.size, k=1)
            parts.append(np.stack([grp[a], grp[b]], axis=1))
    return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.int64)


def permuted_input(frames, seed: int):
    """Descriptors with every frame's rows shuffled, and each feature's true landmark."""
    rng = np.random.default_rng(seed)
    desc, truth = [], []
    for fr in frames:
        perm = rng.permutation(fr.descriptors.shape[0])
        desc.append(fr.descriptors[perm])
        truth.append(fr.landmarks[perm])
    return desc, np.concatenate(truth)


def true_pairs(truth_label: np.ndarray, fpc: np.ndarray) -> np.ndarray:
    """Pairs of features of different frames imaging the same landmark."""
    cam = np.repeat(np.arange(fpc.size), fpc)
    pairs = label_pairs(truth_label)
    return pairs[cam[pairs[:, 0]] != cam[pairs[:, 1]]]


def measure(fn, *args, **kw):
    tracemalloc.start()
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*args, **kw)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return out, wall, cpu, peak / 1e6


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=SHARED_DATA / "cmu_hotel")
    ap.add_argument("--frames", type=int, nargs="+", default=[20, 101])
    ap.add_argument("--graphs", nargs="+", default=["complete", "seq:4", "ring2"])
    ap.add_argument("--descriptors", nargs="+", default=["given", "sift"],
                    choices=DESCRIPTOR_SOURCES)
    ap.add_argument("--seed", type=seed_argument, default=0)
    ap.add_argument("--universe", type=count_argument, default=30,
                    help="the given universe size")
    ap.add_argument("--json", type=Path, default=None, help="also save the records here")
    args = ap.parse_args(argv)
    if args.json:
        check_output_files([("--json", args.json)], overwrite=True)
    k = args.universe
    methods = [("spectral", spectral_sync, {}),
               ("spectral, k given", spectral_sync, {"universe_size": k}),
               ("spectral, k given, all kept", spectral_sync,
                {"universe_size": k, "min_cosine": -1.0}),
               ("clear", clear_sync, {}),
               ("clear, k given", clear_sync, {"universe_size": k})]
    print("| descriptors | frames | graph | links | input closure F1 (P / R) | method | points "
          "| unassigned | P | R | F1 | wall s | CPU s | peak MB |")
    print("|" + "---|" * 14)
    records = []
    for source in args.descriptors:
        for n in args.frames:
            frames = load_landmark_folder(args.data, descriptors=source, frames=n)
            fpc = np.array([fr.descriptors.shape[0] for fr in frames])
            desc, truth_label = permuted_input(frames, args.seed)
            truth = true_pairs(truth_label, fpc)
            m = int(fpc.sum())
            for graph in args.graphs:
                edges = comm_graph(graph, [fr.name for fr in frames])
                links, _ = match_landmark_edges(desc, edges, kind=frames[0].descriptor_kind,
                                                ratio=None, geometry="none")
                inp = PairwiseTruth(truth, m).scores(fpc, links)
                for name, fn, kw in methods:
                    labels, wall, cpu, peak = measure(fn, fpc, links, **kw)
                    s = pairwise_scores(label_pairs(labels), truth, m)
                    rec = {"descriptors": source, "frames": n, "graph": graph,
                           "links": len(links), "input": inp, "method": name,
                           "points": int(np.unique(labels[labels >= 0]).size),
                           "unassigned": int((labels < 0).sum()), **s,
                           "wall_s": wall, "cpu_s": cpu, "peak_mb": peak}
                    records.append(rec)
                    print(f"| {source} | {n} | {graph} | {len(links)} | {inp['f1']:.3f} "
                          f"({inp['precision']:.3f} / {inp['recall']:.3f}) | {name} | "
                          f"{rec['points']} | {rec['unassigned']} | {s['precision']:.3f} | "
                          f"{s['recall']:.3f} | **{s['f1']:.3f}** | {wall:.2f} | {cpu:.2f} | "
                          f"{peak:.0f} |", flush=True)
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"process peak RSS: {rss:.0f} MB")
    if args.json:
        # written beside and renamed into place: a failed write keeps the previous file whole
        write_json_atomic(args.json, {"seed": args.seed, "records": records})
    return 0


if __name__ == "__main__":
    sys.exit(main())
