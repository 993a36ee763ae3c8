"""Benchmark: the default ``make run-formation`` against its OpenCV-only floor, side by side.

Every figure comes from whole processes started by this script, run in turn ``--repeat``
times on the same machine in the same minutes, so that a busy machine slows all of them alike
(medians of each; the ratios are taken pair by pair as well):

- **run**: ``python -m pipeline run-formation`` with default settings (formation d, seed 0,
  SIFT, 640x480, fusion and Rerun recording on), the render cache warm (one untimed run
  before fills it, as any second run on a machine finds it);
- **floor**: ``bench/opencv_floor.py`` on the same 6 images (SIFT + kNN ratio matching +
  ``USAC_MAGSAC`` on the 15 edges, nothing else);
- **imports**: a process that only imports the modules the run imports (read from one
  ``python -X importtime`` run of it, untimed) and ends as the run does, without the
  interpreter's teardown, i.e. the start-up cost of the run's code;
- **help**: ``python -m pipeline --help``.
- **run --no-rerun**: the same run without its Rerun recording, to show what writing the
  recording costs.

Every process runs as a user's Python does, writing and reusing compiled bytecode
(``PYTHONDONTWRITEBYTECODE`` is removed from the children's environment; the warm-up run
compiles the project's modules once). Wall time is measured from spawn to exit, CPU time (user + system) and peak RSS are the
child's own (``os.wait4``). CPU time is the steadier figure on a shared machine: a process
waiting for a core counts wall time but no CPU time.

Stage times come from the run's ``report.json`` and its progress lines (the ``write`` stage);
"outside stages" is the wall time of the run outside them (interpreter start, imports at
load time, argument checks, the report's assembly). Modules a stage imports lazily (pycolmap
in ``triangulation``, Rerun in ``write``) count in that stage; the imports row measures all
imports alone, so it overlaps the others and is not part of the sum.

Prints a table and saves ``runs/bench-run-formation/results.json`` (medians; every process
is kept too).

Targets: run ≤ 2x floor (``ratio``), peak RSS ≤ 300 MiB, ``--help`` ≤ 0.3 s.
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402

from pipeline.commands.options import count_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402

TARGET_RATIO = 2.0
TARGET_RSS_MIB = 300.0
TARGET_HELP_S = 0.3
#: stages whose code lives in pipeline/consistency and pipeline/fusion (their shares are
#: printed apart, so that the rest of the run can be judged on its own)
DISTRIBUTED_STAGES = ("consistency", "fusion")


def _timed(cmd: list[str], env: dict) -> dict:
    """Run ``cmd``; its wall and CPU seconds, peak RSS (MiB), stdout and stderr."""
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
        return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime,
                "peak_rss_mib": usage.ru_maxrss / 1024,  # ru_maxrss in KiB
                "stdout": out.read(), "stderr": err.read()}


def _stage_times(stderr: str) -> dict:
    """``{stage}_s`` from the run's ``[stage] done in X s`` progress lines (all stages, the
    ``write`` stage too, which ``report.json`` cannot hold: it is written inside it)."""
    times = {}
    for m in re.finditer(r"^\[([a-z_-]+)\] done in ([0-9.]+) s$", stderr, re.M):
        times[f"{m.group(1)}_s"] = times.get(f"{m.group(1)}_s", 0.0) + float(m.group(2))
    return times


def _imported_modules(importtime_stderr: str) -> list[str]:
    """Top-level modules of a ``python -X importtime`` log (those imported by the program
    itself, not by another module), minus the interpreter's own start-up."""
    mods = []
    for m in re.finditer(r"^import time:\s+\d+ \|\s+\d+ \| ( *)(\S+)$", importtime_stderr,
                         re.M):
        if not m.group(1) and m.group(2) not in ("site", "encodings", "__main__"):
            mods.append(m.group(2))
    return list(dict.fromkeys(mods))


def _write_images(folder: Path, formation: str, env: dict) -> None:
    """The run's own images (rendered through the same cache) as PNG files, plus K.txt."""
    code = ("import sys, cv2, numpy as np, data_synth\n"
            f"f = data_synth.render({formation!r})\n"
            "for v in f.views:\n"
            f"    cv2.imwrite(str({str(folder)!r} + '/' + v.name + '.png'),"
            " cv2.cvtColor(v.image, cv2.COLOR_RGB2BGR))\n"
            f"np.savetxt({str(folder)!r} + '/K.txt', f.views[0].K)\n")
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, check=True)


@one_line_errors
def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=count_argument, default=5,
                    help="rounds of floor, run, imports, help in turn (default 5)")
    ap.add_argument("--formation", default="d")
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-run-formation"))
    args = ap.parse_args()
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    import data_synth

    # refused by run-formation only once the bench had started (exit 1)
    data_synth.check_formation(args.formation)

    # Python as a user runs it: compiled modules are cached (a PYTHONDONTWRITEBYTECODE left in
    # the environment would recompile the project's ~60 modules in every process)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        images = tmp / "images"
        images.mkdir()
        run_cmd = [sys.executable, "-m", "pipeline", "run-formation",
                   "--formation", args.formation, "--out", str(tmp / "run")]
        floor_cmd = [sys.executable, str(ROOT / "bench" / "opencv_floor.py"), str(images)]
        help_cmd = [sys.executable, "-m", "pipeline", "--help"]
        print("warm-up: one run (fills the render cache), one with -X importtime (what a run "
              "imports), images for the floor", file=sys.stderr)
        _timed(run_cmd, env)
        modules = _imported_modules(_timed([sys.executable, "-X", "importtime", *run_cmd[1:]],
                                           env)["stderr"])
        # a module the run tried and did not find (an optional one) is tried here too
        imports_cmd = [sys.executable, "-c", "import importlib\n"
                       f"for m in {modules!r}:\n"
                       "    try:\n        importlib.import_module(m)\n"
                       "    except ImportError:\n        pass\n"
                       # the run ends without the interpreter's teardown (pipeline.__main__.
                       # entry); so does this process, or the teardown would count as imports
                       "import os\nos._exit(0)\n"]
        _write_images(images, args.formation, env)
        load = [os.getloadavg()[0]]
        runs, floors, imports, helps, bare = [], [], [], [], []
        for k in range(args.repeat):
            f = _timed(floor_cmd, env)
            floors.append({"wall_s": f["wall_s"], "cpu_s": f["cpu_s"],
                           "peak_rss_mib": f["peak_rss_mib"], **json.loads(f["stdout"])})
            r = _timed(run_cmd, env)
            report = json.loads((tmp / "run" / "report.json").read_text())
            # report.json's times (4 decimals), and the write stage from the progress lines
            stages = {f"{s}_s": v for s, v in report["timings_s"].items()}
            lines = _stage_times(r["stderr"])
            stages = {**lines, **stages}
            stages = {s: stages[s] for s in sorted(stages, key=list(lines).index)}
            runs.append({"wall_s": r["wall_s"], "cpu_s": r["cpu_s"],
                         "peak_rss_mib": r["peak_rss_mib"], **stages,
                         "outside_stages_s": r["wall_s"] - sum(stages.values())})
            # the same run without its Rerun recording (--no-rerun): what the recording costs
            b = _timed([*run_cmd[:-1], str(tmp / "run-no-rerun"), "--no-rerun"], env)
            bare.append({k2: b[k2] for k2 in ("wall_s", "cpu_s", "peak_rss_mib")})
            i = _timed(imports_cmd, env)
            imports.append({k2: i[k2] for k2 in ("wall_s", "cpu_s", "peak_rss_mib")})
            h = _timed(help_cmd, env)
            helps.append({k2: h[k2] for k2 in ("wall_s", "cpu_s", "peak_rss_mib")})
            print(f"round {k + 1}/{args.repeat}: floor {f['wall_s']:.2f} s, run "
                  f"{r['wall_s']:.2f} s, run --no-rerun {b['wall_s']:.2f} s, imports {i['wall_s']:.2f} s, --help {h['wall_s']:.2f} s",
                  file=sys.stderr)
        load.append(os.getloadavg()[0])

    def med(rows, key):
        return statistics.median(r[key] for r in rows)

    total, floor = med(runs, "wall_s"), med(floors, "wall_s")
    cpu, floor_cpu = med(runs, "cpu_s"), med(floors, "cpu_s")
    ratios = [r["wall_s"] / f["wall_s"] for r, f in zip(runs, floors, strict=True)]
    cpu_ratios = [r["cpu_s"] / f["cpu_s"] for r, f in zip(runs, floors, strict=True)]
    stage_keys = [s for s in runs[0] if s.endswith("_s") and s not in ("wall_s", "cpu_s")]
    stages = {s: med(runs, s) for s in stage_keys}
    distributed = [sum(r.get(f"{s}_s", 0.0) for s in DISTRIBUTED_STAGES) for r in runs]
    rest = [r["wall_s"] - d for r, d in zip(runs, distributed, strict=True)]
    rest_ratios = [x / f["wall_s"] for x, f in zip(rest, floors, strict=True)]
    rss, floor_rss = med(runs, "peak_rss_mib"), med(floors, "peak_rss_mib")
    imports_s, help_s = med(imports, "wall_s"), med(helps, "wall_s")
    ratio = total / floor

    def spread(values):
        return f"{min(values):.2f}-{max(values):.2f}"

    print(f"\nformation {args.formation}, default settings; medians of {args.repeat} rounds "
          f"(floor, run, imports, --help in turn); load average {load[0]:.1f} -> {load[1]:.1f} "
          f"on {os.cpu_count()} cores")
    print(f"{'':<34}{'median s':>9}{'share':>7}")
    for s, v in stages.items():
        name = s[:-2].replace("_", " ")
        mark = "  (pipeline/" + name + ")" if name in DISTRIBUTED_STAGES else ""
        print(f"  {name:<32}{v:>9.3f}{v / total:>7.0%}{mark}")
    print(f"{'run, whole process':<34}{total:>9.3f}{1:>7.0%}")
    print(f"  {'consistency + fusion':<32}{statistics.median(distributed):>9.3f}"
          f"{statistics.median(distributed) / total:>7.0%}")
    print(f"  {'everything else':<32}{statistics.median(rest):>9.3f}"
          f"{statistics.median(rest) / total:>7.0%}")
    print(f"  {'imports alone (overlaps above)':<32}{imports_s:>9.3f}{imports_s / total:>7.0%}"
          f"   {len(modules)} top-level modules")
    print(f"{'OpenCV floor, whole process':<34}{floor:>9.3f}")
    print(f"\nratio run / floor, wall           {ratio:>6.2f}   pair by pair {spread(ratios)}")
    print(f"ratio run / floor, CPU            {cpu / floor_cpu:>6.2f}   pair by pair "
          f"{spread(cpu_ratios)}   ({cpu:.2f} s / {floor_cpu:.2f} s)")
    print(f"everything but consistency + fusion / floor  {statistics.median(rest_ratios):.2f}"
          f"   pair by pair {spread(rest_ratios)}")
    bare_ratios = [r["wall_s"] / f["wall_s"] for r, f in zip(bare, floors, strict=True)]
    bare_cpu_ratios = [r["cpu_s"] / f["cpu_s"] for r, f in zip(bare, floors, strict=True)]
    print(f"ratio run --no-rerun / floor, wall {statistics.median(bare_ratios):>5.2f}   pair by "
          f"pair {spread(bare_ratios)}   CPU {statistics.median(bare_cpu_ratios):.2f}   "
          f"(peak RSS {med(bare, 'peak_rss_mib'):.0f} MiB)")
    print(f"peak RSS run / floor              {rss:>6.0f} MiB / {floor_rss:.0f} MiB")
    print(f"python -m pipeline --help         {help_s:>6.2f} s")

    def verdict(ok):
        return "met" if ok else "NOT met"

    print(f"targets: ratio <= {TARGET_RATIO:g}: {verdict(ratio <= TARGET_RATIO)}; peak RSS <= "
          f"{TARGET_RSS_MIB:g} MiB: {verdict(rss <= TARGET_RSS_MIB)}; --help <= "
          f"{TARGET_HELP_S:g} s: {verdict(help_s <= TARGET_HELP_S)}")
    results = {"formation": args.formation, "repeat": args.repeat,
               "total_s": total, "floor_s": floor, "ratio": ratio,
               "ratio_per_pair": ratios, "ratio_spread": [float(np.min(ratios)),
                                                          float(np.max(ratios))],
               "cpu_s": cpu, "floor_cpu_s": floor_cpu, "cpu_ratio": cpu / floor_cpu,
               "cpu_ratio_per_pair": cpu_ratios,
               "stages_s": stages,
               "consistency_fusion_s": statistics.median(distributed),
               "rest_s": statistics.median(rest),
               "rest_ratio": statistics.median(rest_ratios),
               "fusion_share": stages.get("fusion_s", 0) / total,
               "consistency_share": stages.get("consistency_s", 0) / total,
               "imports_s": imports_s, "imported_modules": modules,
               "help_s": help_s,
               "peak_rss_mib": rss, "floor_peak_rss_mib": floor_rss,
               "target_ratio": TARGET_RATIO, "target_peak_rss_mib": TARGET_RSS_MIB,
               "target_help_s": TARGET_HELP_S,
               "load_average": load, "cpu_count": os.cpu_count(),
               "no_rerun_ratio": statistics.median(bare_ratios),
               "no_rerun_cpu_ratio": statistics.median(bare_cpu_ratios),
               "no_rerun_peak_rss_mib": med(bare, "peak_rss_mib"),
               "runs": runs, "no_rerun_runs": bare, "floors": floors, "imports": imports, "helps": helps,
               "commands": {"run": "python -m pipeline run-formation --formation "
                                   f"{args.formation} (render cache warm)",
                            "floor": "python bench/opencv_floor.py IMAGES",
                            "no_rerun": "the run with --no-rerun",
                            "imports": "python -c 'import <the run's top-level modules>'",
                            "help": "python -m pipeline --help"}}
    write_json_atomic(Path(args.out) / "results.json", results)
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
