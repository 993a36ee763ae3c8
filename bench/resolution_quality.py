"""Benchmark: which links each resolution cuts, against the truth and an oracle.

For formations a–d × seeds 0–4 (``--first-seed``, ``--seeds``: unseen seeds; SIFT, 640x480,
truth at 2 px) runs on the same matches: the paper's Alg. 1 and the evidence-aware rule (both
distributed, by message passing), the three centralized baselines and the oracle (spurious
links of conflictive sets cut, then the fewest good links). One record per formation × seed × method: good cut, spurious cut,
spurious links inside the input's conflictive sets, spurious left there, pairwise F1 after
resolution, and for the distributed methods rounds, messages, bytes and the round bound
(detection ``≤ d + 1`` per pass; resolution ``≤ n + 1`` per pass for Alg. 1, ``≤ diam(C) + 1``
for the evidence rule, ``diam(C)`` the largest diameter of a conflictive set). Prints the
sums over the runs next to the targets and saves ``runs/bench-resolution/results.json``.

``--merge-radius`` lists the radii within which keypoints of one image are merged at
extraction (the near-duplicate measurement); each radius is one full pass over the runs,
with every method on the same matches (default: the ``paper`` rule's 0.5 px,
``pipeline.matching.features.MERGE_RADIUS_PX`` — the paper gives none — and the evidence
rule's 2 px).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from scipy.sparse.csgraph import connected_components, shortest_path  # noqa: E402

import data_synth  # noqa: E402
from pipeline import validate  # noqa: E402
from pipeline.association import camera_offsets  # noqa: E402
from pipeline.commands.options import count_argument  # noqa: E402
from pipeline.consistency import resolve_conflicts  # noqa: E402
from pipeline.consistency.centralized import baselines, union_find_conflicts  # noqa: E402
from pipeline.consistency.rules import get_rule  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.evaluation.links import link_truth  # noqa: E402
from pipeline.evaluation.metrics import association_pairs, pairwise_scores, true_pairs_all  # noqa: E402
from pipeline.evaluation.oracle import oracle_cut, resolution_scores  # noqa: E402
from pipeline.matching.features import MERGE_RADIUS_PX, extract_all  # noqa: E402
from pipeline.matching.link_evidence import link_evidence  # noqa: E402
from pipeline.matching.pairs import match_edges  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402
from pipeline.stages import check_merge_radius  # noqa: E402
from pipeline.types import Links  # noqa: E402

METHODS = ("paper", "evidence", "drop_conflictive_sets", "keep_first_per_image",
           "quality_merge", "oracle")
SIZE = (640, 480)  # the rendered images, in pixels


def diameters(features_per_camera, links: Links) -> tuple[int, int]:
    """``(d, diam_C)``: largest diameter of an association set and of a conflictive set."""
    off = camera_offsets(features_per_camera)
    M = int(off[-1])
    a, b = off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j
    g = sp.csr_matrix((np.ones(len(links)), (a, b)), shape=(M, M))
    g = (g + g.T).tocsr()
    _, label = connected_components(g, directed=False)
    _, conflictive = union_find_conflicts(features_per_camera, links)
    d = dc = 0
    for lab in np.unique(label[a]).tolist():
        nodes = np.flatnonzero(label == lab)
        dist = shortest_path(g[nodes][:, nodes], unweighted=True, directed=False)
        diam = int(dist.max())
        d = max(d, diam)
        if conflictive[nodes[0]]:
            dc = max(dc, diam)
    return d, dc


def one_run(formation: str, seed: int, merge_radius: float) -> list[dict]:
    fm = data_synth.render(formation, seed=seed, size=SIZE)
    views, edges = fm.views, np.asarray(fm.comm_edges)
    feats = extract_all(views, "sift", 2000, merge_radius)
    matches = match_edges(feats, views, edges)
    links = Links.from_matches(matches)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    truth = np.asarray(link_truth(fm, feats, links, tol_px=2.0), dtype=bool)
    gt = true_pairs_all(fm, feats, tol_px=2.0)
    ev = link_evidence(matches, links, views, feats)
    proj = [v.K @ np.c_[v.R, v.t] for v in views]
    d, diam_c = diameters(m, links)
    n = len(views)
    _, conflictive = union_find_conflicts(m, links)
    base = {"formation": formation, "seed": seed, "links": len(links),
            "conflictive_features": int(conflictive.sum()), "d": d, "diam_conflictive": diam_c,
            "n": n, "merge_radius_px": merge_radius}
    kept_masks: dict[str, np.ndarray] = {}
    dist: dict[str, dict] = {}
    for mode in ("paper", "evidence"):
        t0 = time.perf_counter()
        res = resolve_conflicts(m, edges, links, resolution=mode, link_weight=ev.weight,
                                keypoints=[f.keypoints for f in feats], projections=proj)
        st = res.stats
        passes = st["per_iteration"]
        res_bound = (n + 1) if mode == "paper" else (diam_c + 1)
        dist[mode] = {
            "iterations": st["iterations"], "detection_rounds": st["detection_rounds"],
            "resolution_rounds": st["resolution_rounds"],
            "rounds": st["detection_rounds"] + st["resolution_rounds"],
            "round_bound": sum(d + 1 + (res_bound if p["conflictive_features"] else 0)
                               for p in passes),
            "max_resolution_rounds_per_pass": max(p["resolution_rounds"] for p in passes),
            "resolution_round_bound_per_pass": res_bound,
            "messages": st["messages"], "bytes": st["bytes"],
            "asymmetric_links": st["asymmetric_links"], "seconds": time.perf_counter() - t0}
        kept_masks[mode] = ~res.deleted
    for name, mask in baselines(m, links).items():
        kept_masks[name] = np.asarray(mask, dtype=bool)
    kept_masks["oracle"] = oracle_cut(m, links, truth)
    out = []
    for name in METHODS:
        kept = kept_masks[name]
        rec = {**base, "method": name, **resolution_scores(m, links, truth, kept),
               "f1": pairwise_scores(association_pairs(m, links.subset(kept)), gt,
                                     int(m.sum()))["f1"]}
        rec.update(dist.get(name, {}))
        out.append(rec)
    return out


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--formations", default="abcd")
    ap.add_argument("--seeds", type=count_argument, default=5, help="how many seeds")
    ap.add_argument("--first-seed", type=int, default=0,
                    help="seeds FIRST .. FIRST + SEEDS - 1 (unseen seeds: e.g. 5)")
    ap.add_argument("--merge-radius", default=f"{MERGE_RADIUS_PX},{get_rule('evidence').merge_radius_px}",
                    help="comma-separated radii in pixels")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-resolution"))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    validate.seed(args.first_seed, "--first-seed")  # named, not as the renderer's "seed"
    if not args.formations:
        ap.error("--formations '': give at least one formation, e.g. abcd")
    for f in args.formations:
        data_synth.check_formation(f)
    try:
        radii = [float(x) for x in args.merge_radius.split(",")]
    except ValueError:
        ap.error(f"--merge-radius {args.merge_radius!r}: expected comma-separated radii in "
                 "pixels, e.g. 2,3")
    for radius in radii:  # as run-formation refuses one (a negative one merged nothing)
        check_merge_radius(radius, [SIZE], f"the rendered images ({SIZE[0]}x{SIZE[1]})")

    passes = {}
    for radius in radii:
        passes[str(radius)] = one_pass(args, radius)
    out = Path(args.out)
    write_json_atomic(out / "results.json", {"by_merge_radius": passes, "config": vars(args)})
    print(f"saved {out / 'results.json'}")
    return 0


def one_pass(args, merge_radius: float) -> dict:
    records = []
    for f in args.formations:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            t0 = time.perf_counter()
            records += one_run(f, seed, merge_radius)
            print(f"formation {f} seed {seed}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)

    keys = ("good_cut", "spurious_cut", "spurious_in_sets", "spurious_left")
    sums = {}
    for name in METHODS:
        rs = [r for r in records if r["method"] == name]
        sums[name] = {k: int(sum(r[k] for r in rs)) for k in keys}
        sums[name]["f1_mean"] = float(np.mean([r["f1"] for r in rs]))
        for k in ("rounds", "round_bound", "messages", "bytes"):
            if k in rs[0]:
                sums[name][k] = int(sum(r[k] for r in rs))
    runs = len(records) // len(METHODS)
    inputs = [r for r in records if r["method"] == "oracle"]
    input_sums = {k: int(sum(r[k] for r in inputs))
                  for k in ("links", "conflictive_features", "links_in_sets", "spurious_in_sets")}
    print(f"\nsums over {runs} runs (formations {args.formations}, seeds {args.first_seed}-"
          f"{args.first_seed + args.seeds - 1}, "
          f"merge radius {merge_radius} px)")
    print(f"input: {input_sums['links']} links, {input_sums['conflictive_features']} conflictive "
          f"features, {input_sums['links_in_sets']} links in conflictive sets "
          f"({input_sums['spurious_in_sets']} spurious)")
    print(f"{'method':<24}{'good cut':>9}{'spur cut':>9}{'spur in':>8}{'spur left':>10}"
          f"{'F1 mean':>9}{'rounds':>8}{'bound':>7}{'bytes':>11}")
    for name, s in sums.items():
        print(f"{name:<24}{s['good_cut']:>9}{s['spurious_cut']:>9}{s['spurious_in_sets']:>8}"
              f"{s['spurious_left']:>10}{s['f1_mean']:>9.4f}{s.get('rounds', ''):>8}"
              f"{s.get('round_bound', ''):>7}{s.get('bytes', ''):>11}")
    ev, pa, orc = sums["evidence"], sums["paper"], sums["oracle"]
    by_run = {}
    for r in records:
        by_run.setdefault((r["formation"], r["seed"]), {})[r["method"]] = r
    f1_wins = sum(all(v["evidence"]["f1"] >= v[b]["f1"] for b in METHODS[2:5])
                  for v in by_run.values())
    targets = {
        "spurious_left_fraction": ev["spurious_left"] / max(ev["spurious_in_sets"], 1),
        "spurious_left_target": 0.10,
        "good_cut_vs_oracle": ev["good_cut"] / max(orc["good_cut"], 1),
        "good_cut_target": 1.25,
        "f1_mean_evidence": ev["f1_mean"],
        "f1_mean_best_baseline": max(sums[b]["f1_mean"] for b in METHODS[2:5]),
        "runs_where_f1_beats_every_baseline": f1_wins,
        "runs": runs,
        "rounds_within_bound": all(r["rounds"] <= r["round_bound"]
                                   and r["max_resolution_rounds_per_pass"]
                                   <= r["resolution_round_bound_per_pass"]
                                   for r in records if "rounds" in r),
        "bytes_vs_paper": ev["bytes"] / max(pa["bytes"], 1),
        "bytes_target": 3.0,
    }
    print("\ntargets (evidence):")
    print(f"  spurious left / in sets: {targets['spurious_left_fraction']:.3f} (≤ 0.10)")
    print(f"  good cut / oracle's:     {targets['good_cut_vs_oracle']:.3f} (≤ 1.25)")
    print(f"  mean F1: {ev['f1_mean']:.4f} vs best baseline {targets['f1_mean_best_baseline']:.4f}; "
          f"≥ every baseline in {f1_wins} of {runs} runs")
    print(f"  rounds within bound: {targets['rounds_within_bound']}")
    print(f"  bytes / Alg. 1's:        {targets['bytes_vs_paper']:.3f} (≤ 3)")
    return {"records": records, "input": input_sums, "sums": sums, "targets": targets}


if __name__ == "__main__":
    sys.exit(main())
