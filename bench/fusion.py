"""Benchmark: the fusion stage's consensus schemes side by side, and what their cuts differ in.

    python bench/fusion.py [--formations a b c d] [--resolutions evidence paper] [--sceaux]
                           [--repeat 3] [--size 640x480] [--long-rounds 1000]

For each case (a rendered formation, or the Sceaux photographs with ``--sceaux``, under each
consistency resolution) the input of the fusion stage is built once (defaults of
``run-formation`` / ``run-images``); then the fusion stage runs on it alternately
``--repeat`` times in each mode, so a busy machine slows all alike:

- **fixed**: the paper's scheme as it ran before the stop rules — 100 Metropolis rounds
  (eqs. 2, 6, 11), full float64 bundles on every flat-node edge every round;
- **metropolis**: the same iteration with per-link delta messages, float32 state and the
  stop rule of :mod:`pipeline.fusion.protocol` (capped at 100 rounds);
- **exact** (the default): the flood of :mod:`pipeline.fusion.flooding` and the consensus
  limit computed by each robot (``Diam + 1`` rounds).

Prints rounds (max-c + consensus), messages, bytes, the stage's median wall time
(``fusion_stage``: triangulation, voting, cuts) and, for exact and metropolis, the links whose
cut differs from the fixed scheme. Every such link is explained and classified:

- *not converged at 100*: the fixed scheme run ``--long-rounds`` rounds cuts it as the exact
  mode does (the 100-round scheme read its votes before they settled);
- *tie in <run>*: the robot's two best hypotheses have equal votes in that run (exact counts,
  or Metropolis votes within 1e-3): the winner is decided by the tie rule (lowest hypothesis
  index) or, in the fixed scheme (plain argmax), by round-off;
- *other fixed point*: neither — the paper's iteration, with robots deciding on partially
  mixed estimates, settled on another fixed point of the gate map than the exact one;

and against ground truth (formations): a *good* or a *spurious* link. Saves
``runs/bench-fusion/results.json``. Targets (formation d, exact): bytes <= 25 MB and >= 20x
less than fixed, fusion stage <= 0.3 s.
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402

from pipeline.commands.options import count_argument, parse_size, size_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

MODES = {"fixed": dict(stop=False, consensus="metropolis"),
         "metropolis": dict(consensus="metropolis"),
         "exact": dict(consensus="exact")}
SCEAUX = ROOT / "tests" / "data" / "sceaux_castle_640"
SCEAUX_IMAGES = ("100_7100.JPG", "100_7101.JPG", "100_7102.JPG", "100_7103.JPG")


def _formation_inputs(formation: str, size, resolution: str):
    """The fusion stage's input after the consistency stage on a rendered formation, and the
    ground truth of every link."""
    import data_synth
    from pipeline.evaluation.links import link_truth
    from pipeline.progress import StageTimer
    from pipeline.stages import (
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
                                              merge_radius=merge_radius_for(resolution, None))
    m = np.array([len(x) for x in feats])
    ev = evidence_inputs(f.views, feats, links, matches) if resolution == "evidence" else None
    res, _ = consistency_stage(m, edges, links, resolution=resolution, evidence=ev)
    truth = np.asarray(link_truth(f, feats, links), dtype=np.int8)
    return dict(args=(ledger_from_consistency(res), f.views, feats, edges),
                kwargs=dict(track_labels=res.track_label), truth=truth)


def _sceaux_inputs(resolution: str):
    """The fusion stage's input inside ``run-images`` on four Sceaux photographs (ring2)."""
    import shutil

    import pipeline.stages as run_mod
    from pipeline.progress import StageTimer
    from pipeline.runs.images import ImagesConfig, run_images

    captured = {}
    orig = run_mod.fusion_stage

    def capture(ledger, *args, **kwargs):
        captured.update(args=(copy.deepcopy(ledger), *args), kwargs=dict(kwargs))
        return orig(ledger, *args, **kwargs)

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "sceaux"
        folder.mkdir()
        for name in (*SCEAUX_IMAGES, "K.txt"):
            shutil.copy(SCEAUX / name, folder / name)
        run_mod.fusion_stage = capture
        try:
            run_images(ImagesConfig(str(folder), "ring2", max_size=640, rerun=False,
                                    out=str(Path(tmp) / "out"), resolution=resolution),
                       StageTimer(verbose=False))
        finally:
            run_mod.fusion_stage = orig
    captured["kwargs"].pop("timer", None)
    captured["truth"] = None
    return captured


def _fuse(inputs, **mode):
    """One fusion stage on a copy of the input in a mode; (wall s, FusionResult, cut mask over
    the ledger's links, rounds of fusion per cut)."""
    import pipeline.fusion.landmarks as landmarks
    from pipeline.stages import fusion_stage

    ledger = copy.deepcopy(inputs["args"][0])
    orig = landmarks.fuse_tracks
    landmarks.fuse_tracks = lambda *a, **k: orig(*a, **k, **mode)
    try:
        t0 = time.perf_counter()
        fr, _ = fusion_stage(ledger, *inputs["args"][1:], **inputs["kwargs"])
        wall = time.perf_counter() - t0
    finally:
        landmarks.fuse_tracks = orig
    return wall, fr, ledger.reason == "fusion-outlier"


def _obs_tie(fr, tol: float) -> dict:
    """(cam, feat) -> the robot's two best hypotheses tie (within ``tol``)."""
    v = fr.obs_votes
    if v is None or v.shape[1] < 2:
        return {}
    top = -np.sort(-np.nan_to_num(v, nan=-1.0), axis=1)
    tie = np.abs(top[:, 0] - top[:, 1]) <= tol
    return {(int(c), int(f)): bool(t) for c, f, t in zip(fr.obs_cam, fr.obs_feat, tie, strict=True)}


def _explain(inputs, cuts, frs, long_cut) -> dict:
    """Links cut differently by ``exact``/``metropolis`` and ``fixed``: why, and their truth."""
    links = inputs["args"][0].links
    truth = inputs["truth"]
    cameras = inputs["kwargs"].get("cameras")
    reg = np.arange(len(inputs["args"][1])) if cameras is None else np.asarray(cameras)
    out = {}
    for mode in ("metropolis", "exact"):
        diff = np.flatnonzero(cuts[mode] != cuts["fixed"])
        ties = {"fixed": _obs_tie(frs["fixed"], 1e-3),
                mode: _obs_tie(frs[mode], 1e-9 if mode == "exact" else 1e-3)}
        rows = []
        for k in diff:
            ends = [(int(np.flatnonzero(reg == links.cam_i[k])[0]), int(links.feat_i[k])),
                    (int(np.flatnonzero(reg == links.cam_j[k])[0]), int(links.feat_j[k]))]
            if long_cut is not None and long_cut[k] == cuts[mode][k]:
                why = "not converged at 100"
            elif any(t.get(e, False) for t in ties.values() for e in ends):
                why = "tie in " + " and ".join(m for m, t in ties.items()
                                               if any(t.get(e, False) for e in ends))
            else:
                why = "other fixed point"
            rows.append(dict(link=int(k), cut_by=mode if cuts[mode][k] else "fixed", why=why,
                             truth=None if truth is None else int(truth[k])))
        summary = {}
        for r in rows:
            label = {None: "unknown", 1: "good", 0: "spurious"}[r["truth"]]
            key = f"cut only by {r['cut_by']}: {label}, {r['why']}"
            summary[key] = summary.get(key, 0) + 1
        out[mode] = dict(n=len(rows), summary=summary, links=rows)
    return out


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--formations", nargs="*", default=["a", "b", "c", "d"])
    ap.add_argument("--resolutions", nargs="+", default=["evidence", "paper"])
    ap.add_argument("--sceaux", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--repeat", type=count_argument, default=3)
    ap.add_argument("--size", default="640x480", type=size_argument)
    ap.add_argument("--long-rounds", type=int, default=1000,
                    help="rounds of the fixed scheme that tell 'not converged at 100'")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-fusion"))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    if args.long_rounds <= 100:
        ap.error(f"--long-rounds {args.long_rounds}: more than the fixed scheme's 100 rounds "
                 "(it tells whether a link was cut before its votes settled)")
    size = parse_size(args.size)
    # every formation and rule before the first case runs (a bad one last ran the others first)
    import data_synth
    from pipeline.consistency.rules import get_rule

    for name in args.formations:
        data_synth.check_formation(name)
    for res in args.resolutions:
        get_rule(res)
    import pipeline.fusion.landmarks  # noqa: F401  (imports outside the timings)

    load = [round(x, 2) for x in os.getloadavg()]
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")

    cases = [(f"{name}/{res}", lambda name=name, res=res: _formation_inputs(name, size, res))
             for name in args.formations for res in args.resolutions]
    if args.sceaux:
        cases += [(f"sceaux/{res}", lambda res=res: _sceaux_inputs(res))
                  for res in args.resolutions]
    rows, diffs = [], {}
    for case, make in cases:
        inputs = make()
        times = {m: [] for m in MODES}
        frs, cuts = {}, {}
        for _ in range(args.repeat):
            for mode, kw in MODES.items():
                wall, frs[mode], cuts[mode] = _fuse(inputs, **kw)
                times[mode].append(wall)
        long_cut = None
        if any((cuts[m] != cuts["fixed"]).any() for m in ("exact", "metropolis")):
            _, _, long_cut = _fuse(inputs, stop=False, consensus="metropolis",
                                   rounds=args.long_rounds)
        diffs[case] = _explain(inputs, cuts, frs, long_cut)
        for mode in MODES:
            s = frs[mode].stats
            rows.append(dict(case=case, mode=mode, rounds=int(s["rounds"]),
                             maxc_rounds=int(s["maxc_rounds"]),
                             consensus_rounds=int(s["rounds"] - s["maxc_rounds"]),
                             settled=s.get("settled"), messages=int(s["messages"]),
                             bytes=int(s["bytes"]), links_cut=int(cuts[mode].sum()),
                             differ_from_fixed=(diffs[case][mode]["n"] if mode != "fixed"
                                                else 0),
                             fusion_s=statistics.median(times[mode]),
                             fusion_s_all=times[mode]))
    print(f"{'case':12} {'mode':10} {'rounds':>6} {'(maxc+cons)':>11} {'settled':>7} "
          f"{'messages':>8} {'bytes':>11} {'cut':>4} {'differ':>6} {'fusion s':>8}")
    for r in rows:
        print(f"{r['case']:12} {r['mode']:10} {r['rounds']:6d} "
              f"{'(' + str(r['maxc_rounds']) + '+' + str(r['consensus_rounds']) + ')':>11} "
              f"{str(r['settled']):>7} {r['messages']:8d} {r['bytes']:11d} {r['links_cut']:4d} "
              f"{r['differ_from_fixed']:6d} {r['fusion_s']:8.3f}")
    print("\nlinks cut differently from the fixed 100-round scheme:")
    for case, d in diffs.items():
        for mode in ("exact", "metropolis"):
            if d[mode]["n"]:
                print(f"  {case:12} {mode:10} {d[mode]['n']:3d}: " + "; ".join(
                    f"{v} {k}" for k, v in sorted(d[mode]["summary"].items())))
    ratios = {}
    for case, _ in cases:
        fx = next(r for r in rows if r["case"] == case and r["mode"] == "fixed")
        for mode in ("metropolis", "exact"):
            sr = next(r for r in rows if r["case"] == case and r["mode"] == mode)
            ratios.setdefault(case, {})[mode] = dict(
                bytes_ratio=fx["bytes"] / max(sr["bytes"], 1),
                time_ratio=fx["fusion_s"] / max(sr["fusion_s"], 1e-9))
        print(f"{case}: exact {ratios[case]['exact']['bytes_ratio']:.0f}x fewer bytes, "
              f"{ratios[case]['exact']['time_ratio']:.1f}x faster than fixed; metropolis "
              f"{ratios[case]['metropolis']['bytes_ratio']:.0f}x, "
              f"{ratios[case]['metropolis']['time_ratio']:.1f}x")
    load_end = [round(x, 2) for x in os.getloadavg()]
    print(f"load average at the end: {load_end}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", dict(size=list(size), repeat=args.repeat,
                                                 load_average=dict(start=load, end=load_end),
                                                 long_rounds=args.long_rounds, rows=rows,
                                                 differences=diffs, ratios=ratios,
                                                 targets=dict(d_bytes_max=25_000_000,
                                                              d_bytes_ratio_min=20,
                                                              d_fusion_s_max=0.3)))
    print(f"saved {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
