"""Benchmark: the fusion stage's fixed 100 rounds against its distributed stop rule, side by side.

    python bench/fusion.py [--formations a b c d] [--repeat 3] [--size 640x480]

For each formation: render, features, matching and the consistency stage once (defaults of
``run-formation``), then the fusion stage on the same input alternately ``--repeat`` times in
each mode, so a busy machine slows both alike:

- **fixed**: the paper's scheme as it ran before — 100 consensus rounds, every flat-node edge
  carrying full float64 bundles every round (``fuse_tracks(stop=False)``);
- **stop rule**: per-link delta messages, float32 consensus state and the distributed stop
  rule of :mod:`pipeline.fusion.protocol` (the default).

Prints rounds (max-c + consensus), messages, bytes, the stage's median wall time (the
``fusion_stage`` call: triangulation, voting, cuts) and whether the two cut the same links;
saves ``runs/bench-fusion/results.json``. Targets (formation d): bytes >= 20x less (<= 25 MB),
fusion stage <= 0.3 s.
"""

from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.runfolder import write_json_atomic  # noqa: E402


def _inputs(formation: str, size):
    """The fusion stage's input after the default consistency stage on a rendered formation."""
    import data_synth
    from pipeline.progress import StageTimer
    from pipeline.run import (
        consistency_stage,
        evidence_inputs,
        extract_and_match,
        ledger_from_consistency,
        merge_radius_for,
    )

    f = data_synth.render(formation, seed=0, size=size)
    edges = np.asarray(f.comm_edges)
    feats, matches, links = extract_and_match(f.views, edges, "sift", 2000,
                                              StageTimer(verbose=False),
                                              merge_radius=merge_radius_for("evidence", None))
    m = np.array([len(x) for x in feats])
    res, _ = consistency_stage(m, edges, links, resolution="evidence",
                               evidence=evidence_inputs(f.views, feats, links, matches))
    return ledger_from_consistency(res), f.views, feats, edges, res.track_label


def _fuse(inputs, stop: bool):
    import pipeline.fusion.landmarks as landmarks
    from pipeline.run import fusion_stage

    ledger, views, feats, edges, labels = inputs
    ledger = copy.deepcopy(ledger)
    orig = landmarks.fuse_tracks
    landmarks.fuse_tracks = lambda *a, **k: orig(*a, **k, stop=stop)
    try:
        t0 = time.perf_counter()
        fr, _ = fusion_stage(ledger, views, feats, edges, track_labels=labels)
        wall = time.perf_counter() - t0
    finally:
        landmarks.fuse_tracks = orig
    return wall, fr.stats, ledger.reason == "fusion-outlier"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--formations", nargs="+", default=["a", "b", "c", "d"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-fusion"))
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    import pipeline.fusion.landmarks  # noqa: F401  (imports outside the timings)

    rows = []
    for name in args.formations:
        inputs = _inputs(name, size)
        times = {"fixed": [], "stop rule": []}
        stats, cuts = {}, {}
        for _ in range(args.repeat):
            for mode, stop in (("fixed", False), ("stop rule", True)):
                wall, stats[mode], cuts[mode] = _fuse(inputs, stop)
                times[mode].append(wall)
        same = bool(np.array_equal(cuts["fixed"], cuts["stop rule"]))
        for mode in times:
            s = stats[mode]
            rows.append(dict(formation=name, mode=mode, rounds=int(s["rounds"]),
                             maxc_rounds=int(s["maxc_rounds"]),
                             consensus_rounds=int(s["rounds"] - s["maxc_rounds"]),
                             settled=s.get("settled"), messages=int(s["messages"]),
                             bytes=int(s["bytes"]), links_cut=int(s["links_cut"]),
                             same_cuts_as_fixed=same, fusion_s=statistics.median(times[mode]),
                             fusion_s_all=times[mode]))
    print(f"{'formation':9} {'mode':9} {'rounds':>6} {'(maxc+cons)':>11} {'settled':>7} "
          f"{'messages':>8} {'bytes':>12} {'cut':>4} {'same cuts':>9} {'fusion s':>8}")
    for r in rows:
        print(f"{r['formation']:9} {r['mode']:9} {r['rounds']:6d} "
              f"{'(' + str(r['maxc_rounds']) + '+' + str(r['consensus_rounds']) + ')':>11} "
              f"{str(r['settled']):>7} {r['messages']:8d} {r['bytes']:12d} {r['links_cut']:4d} "
              f"{str(r['same_cuts_as_fixed']):>9} {r['fusion_s']:8.3f}")
    ratios = {}
    for name in args.formations:
        fx = next(r for r in rows if r["formation"] == name and r["mode"] == "fixed")
        sr = next(r for r in rows if r["formation"] == name and r["mode"] == "stop rule")
        ratios[name] = dict(bytes_ratio=fx["bytes"] / max(sr["bytes"], 1),
                            time_ratio=fx["fusion_s"] / max(sr["fusion_s"], 1e-9))
        print(f"{name}: bytes {ratios[name]['bytes_ratio']:.1f}x less, "
              f"fusion stage {ratios[name]['time_ratio']:.1f}x faster")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", dict(size=list(size), repeat=args.repeat,
                                                 rows=rows, ratios=ratios,
                                                 targets=dict(d_bytes_max=25_000_000,
                                                              d_bytes_ratio_min=20,
                                                              d_fusion_s_max=0.3)))
    print(f"saved {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
