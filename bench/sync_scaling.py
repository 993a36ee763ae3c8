"""Benchmark: the ``sync`` rule's simulator on dense and long teams, robot by robot and batched.

Cases (``--cases``):

* ``hotel:F:GRAPH`` — the CMU hotel landmarks (``--data``), ``F`` frames (``all`` = 101) at a
  fixed stride, matched on the communication graph ``GRAPH`` (``complete``, ``ring2``,
  ``seq:4``, ... as ``pipeline.commgraph``), link evidence ``ratio_llr(1 - quality)``;
* ``ring2:N`` — a synthetic team of ``N`` cameras on the ``ring2`` graph, every camera seeing
  the same 30 landmarks (feature order shuffled per camera), every linked pair matching all
  30, and 30 % of the pairs swapping two of their matches (wrong links that make conflicts);
  evidence drawn from a standard normal (seed 0).

Each (engine, flood, case) runs in a child process; the table gives the wall time and CPU
time of ``run_sync`` / ``run_sync_batched`` alone, the rounds, messages and bytes the network
counted, the largest per-robot memory (:attr:`Robot.peak_memory_bytes`) and the child's peak
resident memory (``ru_maxrss`` by ``os.wait4``), plus a digest of every robot's labels and
kept links, which must agree between engines and flood graphs.

Prints the table and saves ``runs/bench-sync-scaling/results.json``.

Usage: ``.venv/bin/python bench/sync_scaling.py [--cases hotel:20:complete ring2:3000]
[--engines robot batched] [--floods links tree] [--timeout 1800]``
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402
from multiway import SHARED_DATA  # noqa: E402

from pipeline.commands.options import positive_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

OUT = ROOT / "runs" / "bench-sync-scaling"
DEFAULT_CASES = ["hotel:20:complete", "hotel:all:complete", "hotel:all:ring2",
                 "hotel:all:seq:4", "ring2:3000"]


def hotel(data: Path, frames: str, graph: str):
    from pipeline.commgraph import comm_graph
    from pipeline.inputs.landmarks import load_landmark_folder
    from pipeline.matching.landmarks import match_landmark_edges
    from pipeline.matching.link_evidence import ratio_llr

    fr = load_landmark_folder(data, "auto", None if frames == "all" else int(frames))
    edges = comm_graph(graph, [f.name for f in fr])
    fpc = np.array([len(f.keypoints) for f in fr])
    links, _ = match_landmark_edges([f.descriptors for f in fr], edges, fr[0].descriptor_kind,
                                    None, [f.keypoints for f in fr], "none", 3.0)
    return fpc, links, edges, ratio_llr(1 - links.quality)


def ring2_team(n: int, m: int = 30, p_swap: float = 0.3, seed: int = 0):
    """``n`` cameras on ``ring2`` seeing the same ``m`` landmarks; a share ``p_swap`` of the
    linked pairs swaps two of their ``m`` matches."""
    from pipeline.commgraph import graph_edges
    from pipeline.types import Links

    rng = np.random.default_rng(seed)
    edges = graph_edges("ring2", n)
    perm = np.argsort(rng.random((n, m)), axis=1)  # perm[i, k]: feature of landmark k in i
    P = len(edges)
    tgt = np.tile(np.arange(m), (P, 1))
    swap = np.flatnonzero(rng.random(P) < p_swap)
    a = rng.integers(0, m, P)[swap]
    b = (a + rng.integers(1, m, P)[swap]) % m
    tgt[swap, a], tgt[swap, b] = b, a
    links = Links(np.repeat(edges[:, 0], m), perm[edges[:, 0]].reshape(-1),
                  np.repeat(edges[:, 1], m), perm[edges[:, 1][:, None], tgt].reshape(-1))
    return np.full(n, m), links, edges, rng.normal(size=len(links))


def child(engine: str, flood: str, case: str, data: Path) -> dict:
    import resource

    from pipeline.consistency.engines.driver import build_robots
    from pipeline.consistency.engines.sync_batched import run_sync
    from pipeline.consistency.sync import equip_sync
    from pipeline.transport.simulated import Network

    if case.startswith("hotel:"):
        _, frames, graph = case.split(":", 2)
        fpc, links, edges, w = hotel(data, frames, graph)
    else:
        fpc, links, edges, w = ring2_team(int(case.split(":")[1]))
    robots, index = build_robots(fpc, links)
    for rb, li in zip(robots, index, strict=True):
        equip_sync(rb, w[li], flood)
    net = Network(len(fpc), edges)
    if engine == "batched":
        from pipeline.consistency.engines.sync_batched import run_sync_batched as run
    else:
        run = run_sync
    t0, c0 = time.perf_counter(), time.process_time()
    res = run(robots, net)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    c = net.counters()
    digest = hashlib.sha1()
    for rb in robots:
        digest.update(rb.sync.label.tobytes())
        digest.update(rb.link_alive.tobytes())
    return dict(engine=engine, flood=flood, case=case, cameras=len(fpc), links=len(links),
                wall_s=round(wall, 3), cpu_s=round(cpu, 3), rounds=res["rounds"],
                boruvka_rounds=res["boruvka_rounds"], messages=c["messages"], bytes=c["bytes"],
                robot_peak_bytes=max(rb.peak_memory_bytes for rb in robots),
                kept=int(sum(int(rb.link_alive.sum()) for rb in robots) // 2),
                digest=digest.hexdigest()[:12],
                rss_mb_in_child=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024))


def run_child(engine: str, flood: str, case: str, data: Path, timeout: float) -> dict:
    cmd = [sys.executable, __file__, "--child", engine, flood, case, "--data", str(data)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    t0 = time.perf_counter()
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() - t0 > timeout:
            proc.kill()
            _, status, usage = os.wait4(proc.pid, 0)
            return dict(engine=engine, flood=flood, case=case, error=f"over {timeout:g} s")
        time.sleep(0.2)
    out = proc.stdout.read().decode().strip().splitlines()
    if os.waitstatus_to_exitcode(status) != 0 or not out:
        err = proc.stderr.read().decode(errors="replace").strip()[-400:]
        return dict(engine=engine, flood=flood, case=case, error=err)
    r = json.loads(out[-1])
    r["peak_rss_mb"] = round(usage.ru_maxrss / 1024)
    return r


def case_problem(case: str) -> str | None:
    """What is wrong with a ``--cases`` entry, or None: ``hotel:F:GRAPH`` (``F`` a count of
    at least 2 or ``all``) or ``ring2:N`` (``N`` at least 2)."""
    kind, _, rest = case.partition(":")
    count = rest.split(":", 1)[0] if kind == "hotel" and ":" in rest else rest
    if kind not in ("hotel", "ring2") or (kind == "hotel" and ":" not in rest):
        return "expected hotel:F:GRAPH or ring2:N, e.g. hotel:20:complete ring2:3000"
    if not (count == "all" and kind == "hotel") and not (count.isdigit() and int(count) >= 2):
        return f"{count!r} is not a count of at least 2 cameras" + (
            " (or all)" if kind == "hotel" else "")
    return None


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=DEFAULT_CASES)
    ap.add_argument("--engines", nargs="+", default=["batched"], choices=["robot", "batched"])
    ap.add_argument("--floods", nargs="+", default=["links"], choices=["links", "tree"])
    ap.add_argument("--data", type=Path, default=SHARED_DATA / "cmu_hotel")
    ap.add_argument("--timeout", type=positive_argument, default=1800.0, help="seconds per child")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--child", nargs=3, metavar=("ENGINE", "FLOOD", "CASE"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    if args.child:
        print(json.dumps(child(*args.child, args.data)))
        return 0
    for case in args.cases:
        if problem := case_problem(case):
            ap.error(f"--cases {case}: {problem}")
    # the children run in the repository: a relative --data is the caller's
    args.data = args.data.absolute()
    if any(c.startswith("hotel:") for c in args.cases) and not args.data.is_dir():
        ap.error(f"--data {args.data}: no such folder of labelled images (the hotel cases "
                 "read it); give the CMU hotel folder, or only ring2:N cases")
    head = (f"{'case':>20} {'engine':>7} {'flood':>5} {'wall s':>8} {'cpu s':>8} {'rounds':>7} "
            f"{'messages':>10} {'bytes':>12} {'robot KB':>8} {'RSS MB':>7} digest")
    print(head)
    records = []
    for case in args.cases:
        for flood in args.floods:
            for engine in args.engines:
                r = run_child(engine, flood, case, args.data, args.timeout)
                records.append(r)
                if "error" in r:
                    print(f"{case:>20} {engine:>7} {flood:>5} error: {r['error']}", flush=True)
                    continue
                print(f"{case:>20} {engine:>7} {flood:>5} {r['wall_s']:>8.2f} {r['cpu_s']:>8.2f} "
                      f"{r['rounds']:>7} {r['messages']:>10} {r['bytes']:>12} "
                      f"{r['robot_peak_bytes'] / 1024:>8.0f} {r['peak_rss_mb']:>7} {r['digest']}",
                      flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    # one file: the figures and what they were measured on are replaced together
    write_json_atomic(args.out / "results.json",
                      dict(meta=dict(python=platform.python_version(), machine=platform.machine(),
                                     load_average=os.getloadavg(), command=" ".join(sys.argv)),
                           records=records))
    print(f"saved {args.out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
