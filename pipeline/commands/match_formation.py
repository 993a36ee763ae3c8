"""``python -m pipeline match-formation``: render a formation, match neighbours only, and print
the first rows of the paper's Table III (Aragüés et al., Sec. V-B) with the ground-truth link
counts the paper could not give, and the time of each stage."""

from __future__ import annotations

import argparse
import math

from pipeline import validate
from pipeline.commands.options import (
    add_feature_options,
    add_memory_option,
    add_scene_options,
    feature_options,
    parse_size,
)
from pipeline.errors import InputError

FORMATIONS = ("a", "b", "c", "d")

# (label, key); the first four are the first rows of the paper's Table III
ROWS = [
    ("Association sets", "association_sets"),
    ("Conflictive sets (c)", "conflictive_sets"),
    ("Number of features m_sum", "m_sum"),
    ("Conflictive features", "conflictive_features"),
    ("Communication edges", "comm_edges"),
    ("Empty associations", "empty_associations"),
    ("Links", "links"),
    ("Good links", "good_links"),
    ("Spurious links", "spurious_links"),
    ("Missing links", "missing_links"),
    ("Raw precision", "precision"),
    ("Features (all cameras)", "features"),
    ("time render [s]", "time_render"),
    ("time features [s]", "time_features"),
    ("time matching [s]", "time_matching"),
    ("time evaluate [s]", "time_evaluate"),
]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--formation", default="d",
                   help="a|b|c|d (comm graphs of increasing cycles) or all (default d)")
    add_feature_options(p)
    add_scene_options(p)
    p.add_argument("--ratio", type=float, default=0.8, help="Lowe ratio test (default 0.8)")
    p.add_argument("--threshold-px", type=float, default=1.0,
                   help="epipolar RANSAC inlier threshold in pixels (default 1)")
    p.add_argument("--tol-px", type=float, default=2.0,
                   help="ground-truth tolerance of a good link in pixels (default 2)")
    add_memory_option(p)


def match_formation(formation: str, seed: int = 0, size: tuple[int, int] = (640, 480),
                    features: str = "sift", max_features: int = 2000, ratio: float = 0.8,
                    threshold_px: float = 1.0, tol_px: float = 2.0, timer=None) -> dict:
    """Render one formation, extract, match along the communication graph, count and evaluate.

    Returns
    -------
    dict
        The :data:`ROWS` keys (Table III counts, links, good / spurious / missing links,
        ``precision``, stage times in seconds) plus ``features_per_camera`` and ``edges``
        (per edge: ``i``, ``j``, ``links``, ``putative``, ``reason``).
    """
    import data_synth
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.evaluation.links import link_counts
    from pipeline.progress import StageTimer
    from pipeline.stages import extract_and_match

    timer = timer or StageTimer(verbose=False)
    t0 = dict(timer.timings)
    with timer.stage("render", f"formation {formation}, seed {seed}, {size[0]}x{size[1]}"):
        f = data_synth.render(formation, seed=seed, size=size)
    feats, matches, links = extract_and_match(f.views, f.comm_edges, features, max_features,
                                              timer, ratio=ratio, threshold_px=threshold_px)
    m = [len(x) for x in feats]
    with timer.stage("evaluate", f"ground truth at {tol_px} px"):
        counts = count_conflicts(AssociationGraph(m, links)).as_dict()
        counts.update(link_counts(f, feats, links, f.comm_edges, tol_px=tol_px))
    spent = {k: v - t0.get(k, 0.0) for k, v in timer.timings.items()}
    return {
        "formation": formation,
        **counts,
        "comm_edges": len(matches),
        "empty_associations": sum(1 for p in matches if not len(p.pairs)),
        "features": int(sum(m)),
        "features_per_camera": m,
        **{f"time_{k}": round(spent.get(k, 0.0), 3)
           for k in ("render", "features", "matching", "evaluate")},
        "edges": [{"i": p.i, "j": p.j, "links": int(len(p.pairs)), "putative": int(p.n_putative),
                   "reason": p.reason} for p in matches],
    }


def _fmt(key: str, v) -> str:
    if isinstance(v, float):
        if math.isnan(v):
            return "–"
        return f"{v:.1%}" if key == "precision" else f"{v:.2f}"
    return str(v)


def table(results: list[dict]) -> str:
    """Markdown table, one column per formation, and the paper's Table III for reference."""
    from pipeline.evaluation.report import PAPER_TABLE_III_IV

    names = [r["formation"] for r in results]
    lines = ["| | " + " | ".join(f"({n})" for n in names) + " | paper (a)–(d) |",
             "|---|" + "---:|" * len(names) + "---|"]
    for label, key in ROWS:
        paper = PAPER_TABLE_III_IV.get(label)
        lines.append(f"| {label} | " + " | ".join(_fmt(key, r[key]) for r in results) + " | "
                     + (", ".join(map(str, paper)) if paper else "") + " |")
    return "\n".join(lines) + "\n"


def run(args) -> int:
    from pipeline.budget import check_formation_memory
    from pipeline.progress import StageTimer

    name = str(args.formation).lower()
    if name not in (*FORMATIONS, "all"):
        raise InputError(f"--formation {args.formation!r}: choose one of a, b, c, d or all")
    method, max_features = feature_options(args)
    size = parse_size(args.size)
    args.tol_px = validate.tolerance_px(args.tol_px)
    args.ratio = validate.lowe_ratio(args.ratio)
    args.threshold_px = validate.tolerance_px(args.threshold_px, "--threshold-px")
    args.seed = validate.seed(args.seed, "--seed")
    # the formations are rendered one at a time, six robots each
    check_formation_memory(6, size, args.max_memory_gb, robots_option=False)
    timer = StageTimer()
    results = [match_formation(n, seed=args.seed, size=size, features=method,
                               max_features=max_features, ratio=args.ratio,
                               threshold_px=args.threshold_px, tol_px=args.tol_px, timer=timer)
               for n in (FORMATIONS if name == "all" else (name,))]
    print(f"# match-formation: seed {args.seed}, {method}, {size[0]}x{size[1]}, "
          f"ratio {args.ratio}, epipolar threshold {args.threshold_px} px, "
          f"ground truth at {args.tol_px} px\n")
    print(table(results))
    for r in results:
        empty = [e for e in r["edges"] if e["reason"]]
        for e in empty:
            print(f"({r['formation']}) edge {e['i']}-{e['j']}: empty association: {e['reason']}")
    return 0
