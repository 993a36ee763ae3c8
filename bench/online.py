"""Benchmark: a team in motion, the online stage next to a batch rerun from scratch.

For each formation size (``--robots``, default 6 and 20; graph ``--graph``, default
``ring2``) the formation drives ``--steps`` steps along the facade
(:func:`data_synth.motion.render_motion`, ``--size``, ``--max-features`` SIFT features per
frame) and :func:`pipeline.runs.online.run_online_steps` associates it online with window
``--window``. Per step it records the online stage's wall time, rounds, messages, bytes and
the largest robot memory (descriptors and keypoints of its window frames plus the stage's
state, :meth:`OnlineAssociation.robot_state_bytes`; ``stage_peak_bytes``: the stage's own
peak per frame as the simulator measures it). Every ``--batch-every`` steps and at the last
step the same rule runs from scratch on all links so far (the batch run, in the same
process right after the step: same machine, same minutes) with the same figures (a robot of
the batch run holds all its frames). After every step the batch ran: pairwise precision / recall / F1 of both
on the scope of :mod:`pipeline.evaluation.online` restricted to the frames taken so far, and
their conflictive sets.

Targets: conflict-free after every step; at the last step the online step costs <= 10 % of
the batch rerun in wall time and in bytes; final F1 >= the batch's; memory per robot follows
the window, not the history (its last-step value over its value at step ``window + hold``,
when the stage's window fills; the
stage's own state every 5 steps, ``memory_curve``, and its last-step value over its value
half-way, ``state_growth_second_half``). ``--no-overturn``: the history repair's earlier
rule (only new links are cut), for comparison. ``--hold H``: a frame's links stay open H steps
after it leaves the matching window (default ``window - 1``; ``--hold 0``: the earlier rule). ``--no-weigh``: only the sets the
detection finds conflictive are weighed by the rule (the earlier rule; default: every set the
step's new links touch, step 2b: :mod:`pipeline.consistency.engines.online_weigh`).
``--no-gather``: the rule's small conflictive sets solved by its own flood of their bundles
to every robot of the set (default: gathered at each set's root, the same cuts).
``--robots-solve``: the sets solved at their roots by the simulator's robots themselves,
each on its own inbox (:mod:`pipeline.consistency.roots`, what robot processes run), instead
of the batched solution counted as a shortest-path tree (the same cuts).

Fusion is off unless ``--fusion``: the batch run is the consistency stage alone, so is the
online one it is compared with.

Prints a table and saves ``runs/bench-online/results.json`` (one entry per formation size;
running one size again replaces its entry).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
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

OUT = ROOT / "runs" / "bench-online"
TARGET_COST = 0.10


def one(robots: int, args) -> dict:
    from pipeline.progress import StageTimer
    from pipeline.runs.online import OnlineConfig, online_report, run_online_steps

    config = OnlineConfig(formation=args.graph, seed=args.seed, size=args.size,
                          max_features=args.max_features, robots=robots, graph=args.graph,
                          steps=args.steps, window=args.window, speed=args.speed,
                          resolution=args.resolution, batch_every=args.batch_every,
                          fusion=args.fusion, rerun=False, overturn=not args.no_overturn,
                          hold=args.hold, weigh=not args.no_weigh,
                          gather=not args.no_gather, robots_solve=args.robots_solve,
                          robots_check=not args.record_check)
    t0 = time.perf_counter()

    def show(r):
        b = r.get("batch")
        print(f"  n={robots} step {r['step']:3d}: {r['links_new']:6d} new, online "
              f"{r['wall_s']:7.3f} s {r['rounds']:3d} rounds {r['bytes'] / 1e6:8.2f} MB "
              f"mem {r['robot_memory_bytes_max'] / 1e6:6.2f} MB"
              + (f" ({r['merge_rounds']} rounds merging {r['large_sets']} sets beyond the "
                 "bundle budget)" if r.get("large_sets") else "")
              + (f" | batch {b['wall_s']:7.3f} s {b['rounds']:3d} rounds "
                 f"{b['bytes'] / 1e6:9.2f} MB mem {b['robot_memory_bytes_max'] / 1e6:6.2f} MB"
                 if b else ""), flush=True)

    batch_steps = None if args.batch_steps is None else {k - 1 for k in args.batch_steps}
    run = run_online_steps(config, StageTimer(verbose=False), batch_steps=batch_steps,
                           on_step=show)
    report = online_report(config, run, StageTimer(verbose=False))
    steps = report["steps"]
    from pipeline.evaluation.online import ScopedTruth, scope_pairs

    oa, seq = run.online, run.sequence
    pairs = scope_pairs(oa.robot, oa.step, seq.comm_edges, args.window,
                        step_edges=seq.step_edges)
    links = oa.all_links()
    at_batch = {}
    for t, kept_b in sorted(run.batch_kept.items()):
        # the scope of the frames taken up to step t (true pairs of later frames left out)
        scope = ScopedTruth(seq.flat, run.features,
                            pairs[(oa.step[pairs[:, 0]] <= t) & (oa.step[pairs[:, 1]] <= t)])
        upto = links.subset(np.arange(len(kept_b)))
        at_batch[t + 1] = {"online": scope.scores(upto.subset(run.online_kept_at(t))),
                           "batch": scope.scores(upto.subset(kept_b))}
    final_step = steps[-1]
    last = steps[-1]
    # the comparison step: the last step, or the last one the batch ran at
    with_batch = [r for r in steps if "batch" in r]
    last = with_batch[-1] if with_batch else last
    b = last.get("batch", {})
    full = args.window + oa.hold  # the step the stage's window fills at
    ref = steps[min(full, len(steps)) - 1]
    f = report["final"]
    summary = {
        "robots": robots, "graph": args.graph, "steps": len(steps), "window": args.window,
        "hold": oa.hold, "memory_reference_step": min(full, len(steps)),
        "images": report["n_images"], "links": f["links"],
        "conflict_free_every_step": report["conflict_free_every_step"],
        "compared_step": last["step"] + 1,
        "last_step": {"online_wall_s": last["wall_s"], "batch_wall_s": b.get("wall_s"),
                      "wall_ratio": last["wall_s"] / b["wall_s"] if b else None,
                      "online_bytes": last["bytes"], "batch_bytes": b.get("bytes"),
                      "bytes_ratio": last["bytes"] / b["bytes"] if b else None,
                      "online_rounds": last["rounds"], "batch_rounds": b.get("rounds"),
                      "online_messages": last["messages"], "batch_messages": b.get("messages"),
                      "online_robot_memory_bytes": last["robot_memory_bytes_max"],
                      "batch_robot_memory_bytes": b.get("robot_memory_bytes_max")},
        "memory_growth": final_step["robot_memory_bytes_max"] / ref["robot_memory_bytes_max"]
        if ref["robot_memory_bytes_max"] else None,
        "online_robot_memory_bytes_last": final_step["robot_memory_bytes_max"],
        # the stage's own state per robot (labels, window links, border links, retired
        # entries), every 5 steps and at the last: it levels off once the window is full
        "memory_curve": [{"step": r["step"] + 1,
                          "robot_memory_bytes_max": r["robot_memory_bytes_max"],
                          "robot_state_bytes_max": r["robot_state_bytes_max"],
                          "retired_entries_max": r.get("retired_entries_max")}
                         for r in steps if (r["step"] + 1) % 5 == 0 or r is final_step],
        "state_growth_second_half": final_step["robot_state_bytes_max"]
        / steps[len(steps) // 2 - 1]["robot_state_bytes_max"]
        if len(steps) >= 2 and steps[len(steps) // 2 - 1]["robot_state_bytes_max"] else None,
        # the history check (step 3): links it cut, its bytes (the robots' own messages with
        # --robots-solve, else the record's estimate of its flood) and the robots' rounds
        "history": {"cut": int(sum(r.get("cut_history", 0) for r in steps)),
                    "bytes": int(sum(r.get("history_bytes", 0) for r in steps)),
                    "rounds": int(sum(r.get("history_rounds", 0) for r in steps))},
        "scores_at_batch_steps": at_batch,
        "final": {k: f[k] for k in ("before", "online", "batch") if k in f},
        "seconds": time.perf_counter() - t0,
    }
    return {"summary": summary, "steps": steps}


def _previous(out: Path) -> dict:
    """The results.json already in ``out`` (``{"runs": []}`` if none); InputError if it is not
    one this bench wrote, so it is neither extended wrongly nor replaced."""
    from pipeline.errors import InputError

    path = out / "results.json"
    if not path.exists():
        return {"runs": []}
    try:
        results = json.loads(path.read_text())
    except (ValueError, OSError) as exc:
        raise InputError(f"{path}: not readable as this bench's results ({exc}); move it away "
                         "or give another --out") from None
    if not (isinstance(results, dict) and isinstance(results.get("runs", []), list)
            and all(isinstance(r, dict) and isinstance(r.get("summary"), dict)
                    and "robots" in r["summary"] for r in results.get("runs", []))):
        raise InputError(f"{path}: not this bench's results (a 'runs' list of entries with a "
                         "'summary'); move it away or give another --out")
    return results


def _fixed(x, digits: int) -> str:
    """``x`` with ``digits`` decimals, or ``–`` where the figure does not exist (no batch run
    to compare with, a step with no memory)."""
    return "–" if x is None else f"{x:.{digits}f}"


@one_line_errors
def main(argv=None) -> int:
    """The bench; a value the online stage refuses (e.g. ``--window 0``, ``--robots 1``) is a
    one-line error naming it, exit status 2, as the command line's."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", type=int, nargs="+", default=[6, 20])
    ap.add_argument("--graph", default="ring2")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--window", type=int, default=3)
    ap.add_argument("--speed", type=float, default=0.15)
    ap.add_argument("--size", type=lambda s: tuple(int(v) for v in s.split("x")),
                    default=(320, 240))
    ap.add_argument("--max-features", type=int, default=300)
    ap.add_argument("--resolution", default="evidence")
    ap.add_argument("--batch-every", type=int, default=10)
    ap.add_argument("--batch-steps", type=int, nargs="+", default=None,
                    help="steps (1-based) at which the batch run goes, instead of every "
                         "--batch-every and the last (the batch rerun's cost grows with the "
                         "history: on a busy machine a large team's last steps take long)")
    ap.add_argument("--seed", type=seed_argument, default=0)
    ap.add_argument("--no-overturn", action="store_true",
                    help="the history repair cuts only new links (the earlier rule), instead of "
                         "weighing the conflictive set's open links again")
    ap.add_argument("--hold", type=int, default=None,
                    help="steps a frame's links stay open after it leaves the matching window "
                         "(default window - 1; 0: final at once, the earlier rule)")
    ap.add_argument("--no-weigh", action="store_true",
                    help="weigh only the conflictive sets of a step (the earlier rule), instead "
                         "of every set the step's new links touch")
    ap.add_argument("--no-gather", action="store_true",
                    help="solve the rule's small conflictive sets by its own flood of their "
                         "bundles to every robot of the set (the earlier stage), instead of "
                         "gathering them at the set's root as the weighing does")
    ap.add_argument("--record-check", action="store_true",
                    help="the record's own history check (step 3), counted by its estimate, "
                         "instead of the robots' protocol (pipeline.consistency.history): the "
                         "same cuts")
    ap.add_argument("--robots-solve", action="store_true",
                    help="the simulator's robots run the roots' protocol themselves "
                         "(pipeline.consistency.roots) instead of its batched solution: the "
                         "same cuts, the protocol's own rounds, messages and bytes")
    ap.add_argument("--fusion", action="store_true",
                    help="fuse the changed tracks after each step (off: the consistency stage "
                         "alone, as the batch run)")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    config = {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items()}
    if args.batch_every < 0:  # it was taken as 0
        ap.error(f"--batch-every {args.batch_every}: expected steps >= 0 (0: no batch rerun, "
                 "or only at --batch-steps)")
    late = [k for k in args.batch_steps or () if not 1 <= k <= args.steps]
    if late:  # a batch step beyond the run was left out without a word
        ap.error(f"--batch-steps {late[0]}: the run has steps 1 to {args.steps}")
    out = Path(args.out)
    _previous(out)  # a results.json this bench cannot extend is refused before the runs
    for n in args.robots:
        r = one(n, args)
        r["config"] = config
        # each formation size replaces its own entry of the results.json found at the time of
        # writing, so sizes can be run by separate invocations (each keeps its options)
        results = _previous(out)
        results["runs"] = sorted([x for x in results.get("runs", [])
                                  if x["summary"]["robots"] != n] + [r],
                                 key=lambda x: x["summary"]["robots"])
        s = r["summary"]
        ls = s["last_step"]
        print(f"n={n}: conflict-free every step {s['conflict_free_every_step']}; step "
              f"{s['compared_step']}: online/batch wall {_fixed(ls['wall_ratio'], 4)}, bytes "
              f"{_fixed(ls['bytes_ratio'], 4)}; robot memory at step {s['steps']} / at step "
              f"{s['memory_reference_step']} (window + hold): {_fixed(s['memory_growth'], 3)}", flush=True)
        print("  robot memory (MB) / stage state (kB) / retired entries, by step: " + ", ".join(
            f"{c['step']}: {c['robot_memory_bytes_max'] / 1e6:.3f} / "
            f"{c['robot_state_bytes_max'] / 1e3:.1f} / {c['retired_entries_max']}"
            for c in s["memory_curve"]) + f"; state last / at step {s['steps'] // 2}: "
            f"{_fixed(s['state_growth_second_half'], 3)}", flush=True)
        h = s["history"]
        print(f"  history check: {h['cut']} links cut, {h['bytes'] / 1e6:.3f} MB"
              + (f", {h['rounds']} rounds of the robots' protocol" if h["rounds"] else
                 " (the record's estimate)"), flush=True)
        for k, sc in s["scores_at_batch_steps"].items():
            print(f"  after step {k}: pairwise F1 online {sc['online']['f1']:.4f} "
                  f"(P {sc['online']['precision']:.4f} R {sc['online']['recall']:.4f}), batch "
                  f"{sc['batch']['f1']:.4f} (P {sc['batch']['precision']:.4f} "
                  f"R {sc['batch']['recall']:.4f})", flush=True)
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(out / "results.json", results)  # saved after each size
    print(f"saved {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
