"""Benchmark: where the robot processes of an online run over Zenoh spend their time.

Runs ``run-formation --steps N --transport zenoh`` (formation d by default, ``--no-rerun``)
with every robot process under cProfile (the ``FORMATION_MATCH_PROFILE_DIR`` hook of
:mod:`pipeline.team.robot`), then adds up the statistics of all robot processes of each kind
of team (``online-match``: the robots' matching of a step; ``resolve``: the rule's stage of
a step; ``online-fusion``: the fusion of the tracks a step changed) and prints, per kind, the robot runs, their summed time and the
functions with the largest cumulative and own time summed over them. cProfile slows Python
calls (a line made of many small calls looks heavier than it is): read it for where to look,
and measure a change with ``bench/online_team.py``. Saves ``runs/bench-team-profile/results.json``.
"""

from __future__ import annotations

import argparse
import os
import pstats
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

from pipeline.commands.options import count_argument  # noqa: E402
from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402
from pipeline.team.teamfile import PROFILE_DIR_ENV  # noqa: E402


def _rows(stats: pstats.Stats, key: str, top: int) -> list[dict]:
    """The ``top`` functions by ``key`` (``cumulative`` or ``tottime``), as dicts."""
    out = []
    for (path, line, name), (_, calls, tt, ct, _) in sorted(
            stats.stats.items(), key=lambda kv: -kv[1][3 if key == "cumulative" else 2])[:top]:
        short = path.split("/pipeline/", 1)[-1] if "/pipeline/" in path else Path(path).name
        out.append({"function": f"{short}:{line}({name})", "calls": int(calls),
                    "tottime_s": round(tt, 3), "cumtime_s": round(ct, 3)})
    return out


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--formation", default="d")
    ap.add_argument("--steps", type=count_argument, default=3)
    ap.add_argument("--no-fusion", action="store_true", help="profile the stage's teams only")
    ap.add_argument("--top", type=count_argument, default=12)
    ap.add_argument("--out", default=str(ROOT / "runs" / "bench-team-profile"))
    args = ap.parse_args(argv)
    if problem := results_folder_problem(args.out):
        ap.error(problem)
    import data_synth

    # refused by run-formation only once the bench had started (exit 1)
    data_synth.check_formation(args.formation)
    load = [round(x, 2) for x in os.getloadavg()]
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")
    cmd = ["run-formation", "--steps", str(args.steps), "--formation", args.formation,
           "--transport", "zenoh", "--no-rerun"] + (["--no-fusion"] if args.no_fusion else [])
    with tempfile.TemporaryDirectory() as tmp:
        prof = Path(tmp) / "profiles"
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "pipeline", *cmd, "--out",
                               str(Path(tmp) / "run")], cwd=ROOT, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, env={**os.environ, PROFILE_DIR_ENV: str(prof)})
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"run-formation failed: {proc.stderr.decode(errors='replace')[-500:]}")
        kinds: dict[str, list[Path]] = {}
        for f in sorted(prof.glob("*.pstats")):
            # the team's name without a step number (online-match-3: online-match)
            kinds.setdefault(re.sub(r"-\d+$", "", f.name.rsplit("-", 2)[0]), []).append(f)
        results = {"command": cmd, "wall_s": round(wall, 2), "load_average_at_start": load,
                   "teams": {}}
        print(f"{' '.join(cmd)}: {wall:.2f} s with every robot process profiled")
        for kind, files in sorted(kinds.items()):
            stats = pstats.Stats(str(files[0]))
            for f in files[1:]:
                stats.add(str(f))
            cum, own = _rows(stats, "cumulative", args.top), _rows(stats, "tottime", args.top)
            results["teams"][kind] = {"robot_runs": len(files),
                                      "profiled_s": round(stats.total_tt, 2),
                                      "by_cumulative": cum, "by_own_time": own}
            print(f"\n{kind}: {len(files)} robot runs, {stats.total_tt:.2f} s profiled in all")
            for title, rows in (("cumulative", cum), ("own time", own)):
                print(f"  top by {title}:")
                for r in rows:
                    print(f"    {r['cumtime_s']:9.2f} {r['tottime_s']:9.2f} {r['calls']:9d}  "
                          f"{r['function']}")
    write_json_atomic(Path(args.out) / "results.json", results)
    print(f"saved {args.out}/results.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
