"""Benchmark: why the online association keeps more spurious links than the batch run.

For each ``--hold`` (default 0 and the default hold, ``window - 1``) the 6-robot formation
of :mod:`bench.online` (``--seed``, ``--steps``, window ``--window``, the evidence rule,
fusion off) is associated online, the batch run goes at the last step, and every link gets
its truth (:func:`pipeline.evaluation.links.link_truth`). It counts:

* per history repair (step 3, :mod:`pipeline.consistency.engines.online_history`): the links it
  cut and how many were good, split by whether the repaired set held a spurious link between
  two retired frames (final, so the repair had to cut an open link instead);
* per link at the end: spurious links the online run keeps and the batch run cuts, and of
  them how many were ever, while open, in a conflictive set of a step's sub-problem (else
  the online run never weighed them: their set was never conflictive online);
* good links the online run cut and the batch kept, by reason.

The counts are read by wrapping the stage's methods (measurement only, the decisions are
the stage's own). Prints a table and saves ``runs/bench-online-cuts/results.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402

from pipeline.commands.options import seed_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

OUT = ROOT / "runs" / "bench-online-cuts"


def one(args, hold: int) -> dict:
    from pipeline.consistency.engines import online as eng
    from pipeline.consistency.engines.online_detection import _duplicated_keys
    from pipeline.evaluation.links import link_truth
    from pipeline.progress import StageTimer
    from pipeline.runs.online import OnlineConfig, run_online_steps

    repairs, in_conflict, in_touched = [], set(), set()
    rebuild, check = eng.OnlineAssociation._rebuild, eng.OnlineAssociation._history_check

    def rebuild_counted(self, sub, members, links_c, border_c, img_of, entries):
        skipped = rebuild(self, sub, members, links_c, border_c, img_of, entries)
        a_b, b_b = self._ends(border_c)
        win_a = self.piece[a_b] < 0
        pieces = np.unique(np.concatenate([entries[0], self.piece[np.where(win_a, b_b, a_b)]]))
        a, b = self._ends(np.arange(len(self.links.ci)))
        pa, pb = self.piece[a], self.piece[b]
        final = np.flatnonzero(self.links.kept & (pa >= 0) & (pb >= 0) & np.isin(pa, pieces))
        repairs.append((skipped, final))
        return skipped

    def check_counted(self, sub, real, hist_a, hist_b, att_f, att_p, t, robots=None):
        L = self.links
        was = real[L.kept[real] | (L.step_cut[real] == t)]  # before the rule's cuts
        in_touched.update(was.tolist())
        a, b = self._ends(was)
        comp = self._components(sub, np.concatenate([a, hist_a]), np.concatenate([b, hist_b]))
        img = np.searchsorted(self.offset, sub, side="right") - 1
        bad = _duplicated_keys(comp, img)
        in_conflict.update(was[np.isin(comp[np.searchsorted(sub, a)], bad)].tolist())
        return check(self, sub, real, hist_a, hist_b, att_f, att_p, t, robots)

    config = OnlineConfig(formation=args.graph, seed=args.seed, size=args.size,
                          max_features=args.max_features, robots=args.robots,
                          graph=args.graph, steps=args.steps, window=args.window,
                          speed=args.speed, resolution=args.resolution, batch_every=0,
                          fusion=False, rerun=False, hold=hold)
    eng.OnlineAssociation._rebuild = rebuild_counted
    eng.OnlineAssociation._history_check = check_counted
    try:
        run = run_online_steps(config, StageTimer(verbose=False),
                               batch_steps={args.steps - 1})
    finally:
        eng.OnlineAssociation._rebuild = rebuild
        eng.OnlineAssociation._history_check = check
    oa, seq = run.online, run.sequence
    truth = np.asarray(link_truth(seq.flat, run.features, oa.all_links(), tol_px=2.0), bool)
    L, kb = oa.links, ~run.batch.deleted
    split = {True: [0, 0, 0], False: [0, 0, 0]}
    for skipped, final in repairs:
        s = split[bool((~truth[final]).any())]
        s[0] += 1
        s[1] += len(skipped)
        s[2] += int(truth[skipped].sum())
    ever = np.zeros(len(truth), bool)
    ever[sorted(in_conflict)] = True
    touched = np.zeros(len(truth), bool)
    touched[sorted(in_touched)] = True
    extra = L.kept & ~truth & ~kb
    lost = ~L.kept & truth & kb
    return {
        "hold": hold, "links": int(len(truth)), "good_links": int(truth.sum()),
        "online": {"kept": int(L.kept.sum()), "spurious_kept": int((L.kept & ~truth).sum())},
        "batch": {"kept": int(kb.sum()), "spurious_kept": int((kb & ~truth).sum())},
        "history_repairs": {
            "with_final_spurious_link": dict(zip(("sets", "cuts", "good_cuts"), split[True],
                                                 strict=True)),
            "without": dict(zip(("sets", "cuts", "good_cuts"), split[False], strict=True))},
        "spurious_kept_online_cut_by_batch": int(extra.sum()),
        "of_them_in_a_conflictive_set_while_open": int((extra & ever).sum()),
        "of_them_in_a_touched_set_while_open": int((extra & touched).sum()),
        "good_cut_online_kept_by_batch": {str(r): int((lost & (L.reason == r)).sum())
                                          for r in sorted(set(L.reason[lost]))},
    }


def _by_reason(counts: dict) -> str:
    """``{reason: links}`` as ``N (N1 by REASON1, ...)``, or ``0``."""
    total = sum(counts.values())
    parts = ", ".join(f"{v} by {k}" for k, v in sorted(counts.items()) if v)
    return f"{total} ({parts})" if parts else "0"


@one_line_errors
def main(argv=None) -> int:
    """The bench; a value the online stage refuses (e.g. ``--window 0``, ``--robots 1``) is a
    one-line error naming it, exit status 2, as the command line's."""
    from pipeline.consistency.engines.online import default_hold

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", type=int, default=6)
    ap.add_argument("--graph", default="ring2")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--window", type=int, default=3)
    ap.add_argument("--hold", type=int, nargs="+", default=None)
    ap.add_argument("--speed", type=float, default=0.15)
    ap.add_argument("--size", type=lambda s: tuple(int(v) for v in s.split("x")),
                    default=(320, 240))
    ap.add_argument("--max-features", type=int, default=300)
    ap.add_argument("--resolution", default="evidence")
    ap.add_argument("--seed", type=seed_argument, default=0)
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    holds = args.hold if args.hold is not None else [0, default_hold(args.window)]
    runs = []
    for h in holds:
        r = one(args, h)
        runs.append(r)
        w, wo = r["history_repairs"]["with_final_spurious_link"], r["history_repairs"]["without"]
        print(f"hold {h}: spurious kept online {r['online']['spurious_kept']}, batch "
              f"{r['batch']['spurious_kept']}; history repairs in sets with a spurious final "
              f"link: {w['sets']} sets, {w['cuts']} cuts, {w['good_cuts']} good; without: "
              f"{wo['sets']} sets, {wo['cuts']} cuts, {wo['good_cuts']} good; spurious kept "
              f"online but cut by batch {r['spurious_kept_online_cut_by_batch']}, of them "
              f"{r['of_them_in_a_conflictive_set_while_open']} ever in a conflictive set "
              f"while open, {r['of_them_in_a_touched_set_while_open']} in a set a step's new "
              f"links touched while open; good cut online but kept by batch "
              f"{_by_reason(r['good_cut_online_kept_by_batch'])}", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    config = {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items()}
    write_json_atomic(out / "results.json", {"config": config, "runs": runs})
    print(f"saved {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
