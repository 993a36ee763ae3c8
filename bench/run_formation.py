"""Benchmark: the default ``make run-formation`` end to end, split by stage.

Runs the default formation (d, seed 0, SIFT, 640x480) ``--repeat`` times in this process and
prints each stage's median wall time next to the 10 s target. Saves
``runs/bench-run-formation/results.json``. The first run also pays for imports.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.progress import StageTimer  # noqa: E402
from pipeline.run import FormationConfig, run_formation  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--formation", default="d")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-run-formation"))
    args = ap.parse_args()

    runs = []
    for k in range(args.repeat):
        timer = StageTimer(verbose=False)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            run_formation(FormationConfig(formation=args.formation, out=f"{tmp}/run"), timer)
            total = time.perf_counter() - t0
        runs.append({"total_s": total, **{f"{s}_s": v for s, v in timer.timings.items()}})
        print(f"run {k + 1}/{args.repeat}: {total:.2f} s", file=sys.stderr)
    keys = list(runs[0])
    med = {k: statistics.median(r[k] for r in runs) for k in keys}
    print(f"\nformation {args.formation}, default settings, median of {args.repeat} runs")
    print(f"{'stage':<24}{'median s':>10}{'share':>8}")
    for k in keys:
        share = med[k] / med["total_s"] if med["total_s"] else 0
        print(f"{k:<24}{med[k]:>10.3f}{share:>8.0%}")
    stages = {k: v for k, v in med.items() if k != "total_s"}
    dominant = max(stages, key=stages.get)
    print(f"target: total < 10 s → {'met' if med['total_s'] < 10 else 'NOT met'}; "
          f"dominant stage: {dominant}")
    write_json_atomic(Path(args.out) / "results.json",
                      {"runs": runs, "median": med, "dominant_stage": dominant,
                       "target_total_s": 10.0})
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
