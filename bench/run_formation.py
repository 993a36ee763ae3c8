"""Benchmark: the default ``make run-formation`` against its OpenCV-only floor, side by side.

Both are whole processes started by this script, run alternately ``--repeat`` times on the
same machine in the same minutes, so that a busy machine slows both alike:

- **run**: ``python -m pipeline run-formation`` with default settings (formation d, seed 0,
  SIFT, 640x480, fusion and Rerun recording on), the render cache warm (one untimed run
  before fills it, as any second run on a machine finds it);
- **floor**: ``bench/opencv_floor.py`` on the same 6 images (SIFT + kNN ratio matching +
  ``USAC_MAGSAC`` on the 15 edges, nothing else).

Wall time is measured from spawn to exit; peak RSS is the child's ``ru_maxrss`` (from
``os.wait4``, the per-child form of ``getrusage(RUSAGE_CHILDREN)``). Stage times come from the
run's ``report.json`` and its progress lines (the ``write`` stage); "imports and other" is the
wall time outside the stages (interpreter start, imports, argument checks). Prints a table
and saves ``runs/bench-run-formation/results.json`` (medians; every run is kept too).

Targets: run ≤ 2x floor (``ratio``), peak RSS ≤ 300 MiB.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.runfolder import write_json_atomic  # noqa: E402

TARGET_RATIO = 2.0
TARGET_RSS_MIB = 300.0


def _timed(cmd: list[str], env: dict) -> tuple[float, float, str, str]:
    """Run ``cmd``; its wall seconds, peak RSS (MiB), stdout and stderr."""
    with tempfile.TemporaryFile(mode="w+") as out, tempfile.TemporaryFile(mode="w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if proc.returncode:
            raise SystemExit(f"{' '.join(cmd)} failed with exit code {proc.returncode}:\n"
                             + err.read()[-2000:])
        return wall, usage.ru_maxrss / 1024, out.read(), err.read()  # ru_maxrss in KiB


def _stage_times(stderr: str) -> dict:
    """``{stage}_s`` from the run's ``[stage] done in X s`` progress lines (all stages, the
    ``write`` stage too, which ``report.json`` cannot hold: it is written inside it)."""
    times = {}
    for m in re.finditer(r"^\[([a-z_-]+)\] done in ([0-9.]+) s$", stderr, re.M):
        times[f"{m.group(1)}_s"] = times.get(f"{m.group(1)}_s", 0.0) + float(m.group(2))
    return times


def _write_images(folder: Path, formation: str, env: dict) -> None:
    """The run's own images (rendered through the same cache) as PNG files, plus K.txt."""
    code = ("import sys, cv2, numpy as np, data_synth\n"
            f"f = data_synth.render({formation!r})\n"
            "for v in f.views:\n"
            f"    cv2.imwrite(str({str(folder)!r} + '/' + v.name + '.png'),"
            " cv2.cvtColor(v.image, cv2.COLOR_RGB2BGR))\n"
            f"np.savetxt({str(folder)!r} + '/K.txt', f.views[0].K)\n")
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, check=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="alternating pairs (default 3)")
    ap.add_argument("--formation", default="d")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-run-formation"))
    args = ap.parse_args()

    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        images = tmp / "images"
        images.mkdir()
        run_cmd = [sys.executable, "-m", "pipeline", "run-formation",
                   "--formation", args.formation, "--out", str(tmp / "run")]
        floor_cmd = [sys.executable, str(ROOT / "bench" / "opencv_floor.py"), str(images)]
        print("warm-up: one run (fills the render cache), images for the floor",
              file=sys.stderr)
        _timed(run_cmd, env)
        _write_images(images, args.formation, env)
        load = [os.getloadavg()[0]]
        runs, floors = [], []
        for k in range(args.repeat):
            wall, rss, out, _ = _timed(floor_cmd, env)
            floors.append({"wall_s": wall, "peak_rss_mib": rss, **json.loads(out)})
            wall, rss, _, err = _timed(run_cmd, env)
            report = json.loads((tmp / "run" / "report.json").read_text())
            # report.json's times (4 decimals), and the write stage from the progress lines
            stages = {f"{s}_s": v for s, v in report["timings_s"].items()}
            stages = {**_stage_times(err), **stages}
            stages = {k: stages[k] for k in sorted(stages, key=list(_stage_times(err)).index)}
            runs.append({"wall_s": wall, "peak_rss_mib": rss, **stages,
                         "imports_and_other_s": wall - sum(stages.values())})
            print(f"pair {k + 1}/{args.repeat}: floor {floors[-1]['wall_s']:.2f} s, "
                  f"run {wall:.2f} s", file=sys.stderr)
        load.append(os.getloadavg()[0])

    def med(rows, key):
        return statistics.median(r[key] for r in rows)

    total, floor = med(runs, "wall_s"), med(floors, "wall_s")
    ratios = [r["wall_s"] / f["wall_s"] for r, f in zip(runs, floors, strict=True)]
    stage_keys = [k for k in runs[0] if k.endswith("_s") and k != "wall_s"]
    stages = {k: med(runs, k) for k in stage_keys}
    rss, floor_rss = med(runs, "peak_rss_mib"), med(floors, "peak_rss_mib")
    ratio = total / floor

    print(f"\nformation {args.formation}, default settings; median of {args.repeat} alternating "
          f"pairs; load average {load[0]:.1f} -> {load[1]:.1f} on {os.cpu_count()} cores")
    print(f"{'':<26}{'median s':>10}{'share':>8}")
    for k, v in stages.items():
        print(f"  {k[:-2]:<24}{v:>10.3f}{v / total:>8.0%}")
    print(f"{'run (whole process)':<26}{total:>10.3f}{1:>8.0%}")
    print(f"{'OpenCV floor':<26}{floor:>10.3f}")
    print(f"{'ratio run / floor':<26}{ratio:>10.2f}   per pair: "
          + ", ".join(f"{r:.2f}" for r in ratios))
    print(f"{'peak RSS run / floor':<26}{rss:>7.0f} MiB / {floor_rss:.0f} MiB")
    print(f"targets: ratio <= {TARGET_RATIO:g} -> {'met' if ratio <= TARGET_RATIO else 'NOT met'}; "
          f"peak RSS <= {TARGET_RSS_MIB:g} MiB -> "
          f"{'met' if rss <= TARGET_RSS_MIB else 'NOT met'}; "
          f"fusion takes {stages.get('fusion_s', 0) / total:.0%} of the run")
    results = {"formation": args.formation, "repeat": args.repeat,
               "total_s": total, "floor_s": floor, "ratio": ratio,
               "ratio_per_pair": ratios, "ratio_spread": [float(np.min(ratios)),
                                                          float(np.max(ratios))],
               "stages_s": stages, "peak_rss_mib": rss, "floor_peak_rss_mib": floor_rss,
               "fusion_share": stages.get("fusion_s", 0) / total,
               "target_ratio": TARGET_RATIO, "target_peak_rss_mib": TARGET_RSS_MIB,
               "load_average": load, "cpu_count": os.cpu_count(),
               "runs": runs, "floors": floors,
               "commands": {"run": "python -m pipeline run-formation --formation "
                                   f"{args.formation} (render cache warm)",
                            "floor": "python bench/opencv_floor.py IMAGES"}}
    write_json_atomic(Path(args.out) / "results.json", results)
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
