"""Benchmark: formations a–d next to the paper's Tables III–IV, as the README shows them.

    python bench/formations.py [--out runs/bench-formations]

Runs ``python -m pipeline run-formations`` (SIFT, 640x480, seed 0, ``--resolution paper``,
the paper's rule, as the command does by default; ground truth at 2 px) as a whole process
and prints, with the load average at the start and the end, the README's table: conflictive
sets and features, sets well / wrongly solved (Table IV), links deleted by resolution (good / spurious), sets left, links cut by
fusion (spurious among them), pairwise precision before and after, beside the paper's
figures, and the raw link precision of matching. Every figure is a count: the load does not
change them. The command's own fuller tables are in ``OUT/formations.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

from pipeline.errors import one_line_errors  # noqa: E402
from pipeline.evaluation.report import PAPER_TABLE_III_IV as _P  # noqa: E402

#: the paper's Tables III–IV (SURF on real images, good / spurious counted by hand; its
#: Table IV rows read as pipeline.evaluation.report.PAPER_TABLE_III_IV reads them)
PAPER = {"Conflictive sets": ", ".join(map(str, _P["Conflictive sets (c)"])),
         "Conflictive features": ", ".join(map(str, _P["Conflictive features"])),
         "Conflictive sets well / wrongly solved": ", ".join(
             f"{w}/{x}" for w, x in zip(_P["Inconsistencies well solved"],
                                        _P["Inconsistencies wrongly solved"], strict=True)),
         "Links deleted by resolution (good / spurious)": ", ".join(
             f"{d} ({g}/{s})" for d, g, s in zip(_P["Deleted links"], _P["Good deleted links"],
                                                 _P["Spurious deleted links"], strict=True)),
         "Conflictive sets after": "0"}


def table(reports: dict[str, dict]) -> str:
    """The README's table: one column per formation, then the paper's."""
    rows = {
        "Conflictive sets": lambda r: r["before"]["conflictive_sets"],
        "Conflictive features": lambda r: r["before"]["conflictive_features"],
        "Conflictive sets well / wrongly solved": lambda r: (
            f"{r['resolution']['sets_well_solved']}/{r['resolution']['sets_wrongly_solved']}"),
        "Links deleted by resolution (good / spurious)": lambda r: (
            f"{r['resolution']['deleted_links']} ({r['resolution']['good_deleted']}/"
            f"{r['resolution']['spurious_deleted']})"),
        "Conflictive sets after": lambda r: r["after"]["conflictive_sets"],
        "Links cut by fusion (spurious among them)": lambda r: (
            f"{r['fusion']['links_cut']} ({r['fusion']['cut_spurious']})"),
        "Pairwise precision before → after": lambda r: (
            f"{r['pairwise']['before']['precision']:.3f} → "
            f"{r['pairwise']['after']['precision']:.3f}"),
    }
    names = list(reports)
    lines = ["| | " + " | ".join(f"({n})" for n in names) + " | paper (a)–(d) |",
             "|---|" + "---:|" * len(names) + "---|"]
    lines += [f"| {label} | " + " | ".join(str(fmt(reports[n])) for n in names)
              + f" | {PAPER.get(label, '–')} |" for label, fmt in rows.items()]
    return "\n".join(lines)


@one_line_errors
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench-formations")
    args = ap.parse_args(argv)
    args.out = args.out.absolute()  # run-formations runs in the repository: a relative --out
    # is the caller's
    load = [round(x, 2) for x in os.getloadavg()]
    print(f"{os.cpu_count()} cores; load average at the start (1, 5, 15 min): {load}")
    done = subprocess.run([sys.executable, "-m", "pipeline", "run-formations", "--out",
                           str(args.out), "--overwrite", "--quiet"], cwd=ROOT,
                          capture_output=True, text=True)
    if done.returncode != 0:
        print(done.stderr, file=sys.stderr)
        return done.returncode
    reports = json.loads((args.out / "formations.json").read_text())
    print(table(reports))
    d = reports["d"]["before"]
    print(f"\nraw link precision of matching on (d): {d['good_links'] / d['links']:.1%} "
          f"({d['good_links']} good of {d['links']} links)")
    print(f"load average at the end: {[round(x, 2) for x in os.getloadavg()]}")
    print(f"the command's tables: {args.out / 'formations.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
