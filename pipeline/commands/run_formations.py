"""``python -m pipeline run-formations``: formations a–d side by side, as the paper's
Tables III and IV, plus what the paper could not count without ground truth."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
from pathlib import Path

from pipeline.commands.options import (
    add_feature_options,
    add_memory_option,
    add_merge_radius_option,
    add_resolution_option,
    add_scene_options,
    add_transport_option,
    feature_options,
    parse_size,
)
from pipeline.evaluation.metrics import score_text
from pipeline.evaluation.report import PAPER_TABLE_III_IV

FORMATIONS = ("a", "b", "c", "d")

# (label, section, key) rows; section None = top level of the report
TABLE_ROWS = [
    ("Association sets", "before", "association_sets"),
    ("Conflictive sets (c)", "before", "conflictive_sets"),
    ("Number of features m_sum", "before", "m_sum"),
    ("Conflictive features", "before", "conflictive_features"),
    ("Inconsistencies well solved", "resolution", "sets_well_solved"),
    ("Inconsistencies wrongly solved", "resolution", "sets_wrongly_solved"),
    ("Deleted links", "resolution", "deleted_links"),
    ("Good deleted links", "resolution", "good_deleted"),
    ("Spurious deleted links", "resolution", "spurious_deleted"),
    ("Iterations", "resolution", "iterations"),
    ("Detection rounds", "resolution", "detection_rounds"),
    ("Resolution rounds", "resolution", "resolution_rounds"),
    ("Messages", "resolution", "messages"),
    ("Good links before", "before", "good_links"),
    ("Spurious links before", "before", "spurious_links"),
    ("Missing links before", "before", "missing_links"),
    ("Good links after", "after", "good_links"),
    ("Spurious links after", "after", "spurious_links"),
    ("Missing links after", "after", "missing_links"),
    ("Conflictive sets after", "after", "conflictive_sets"),
    ("Fusion: links cut", "fusion", "cut_links"),
    ("Fusion: spurious among them", "fusion", "cut_spurious"),
]

def add_arguments(p: argparse.ArgumentParser) -> None:
    add_feature_options(p)
    add_scene_options(p)
    p.add_argument("--out", default="runs", help="parent folder of the runs (default runs)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace formations.md / formations.json in --out even when they were "
                        "not written by run-formations (default: refuse)")
    # the paper's Tables III and IV are Alg. 1's figures
    add_resolution_option(p, default="paper")
    add_transport_option(p)
    add_merge_radius_option(p)
    add_memory_option(p)


def _fmt(v) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.3f}"
    return str(v)


def formations_table(reports: dict[str, dict]) -> str:
    """Markdown: our figures for each formation next to the paper's."""
    names = list(reports)
    head = "| | " + " | ".join(f"({n})" for n in names) + " | paper (a)–(d) |"
    lines = [head, "|---|" + "---:|" * len(names) + "---|"]
    for label, section, key in TABLE_ROWS:
        vals = [reports[n].get(section, {}).get(key) for n in names]
        paper = PAPER_TABLE_III_IV.get(label)
        lines.append(f"| {label} | " + " | ".join(_fmt(v) for v in vals) + " | "
                     + (", ".join(map(str, paper)) if paper else "") + " |")
    lines += ["", "Pairwise precision / recall / F1 of the final association (and baselines):", "",
              "| method | " + " | ".join(f"({n})" for n in names) + " |",
              "|---|" + "---|" * len(names)]

    def prf(s):
        return " / ".join(score_text(s, key) for key in ("precision", "recall", "f1"))

    lines.append("| matching only (before) | " + " | ".join(
        prf(reports[n]["pairwise"]["before"]) for n in names) + " |")
    lines.append("| distributed resolution | " + " | ".join(
        prf(reports[n]["pairwise"]["after_resolution"]) for n in names) + " |")
    lines.append("| distributed resolution + fusion | " + " | ".join(
        prf(reports[n]["pairwise"]["after"]) for n in names) + " |")
    for bl in reports[names[0]].get("baselines", {}):
        lines.append(f"| {bl} (centralized) | " + " | ".join(
            prf(reports[n]["baselines"][bl]["pairwise"]) for n in names) + " |")
    quality = [reports[n].get("resolution_quality") for n in names]
    if all(quality):
        lines += ["", "Links cut by each resolution on the same input, against the truth: good cut / "
                  "spurious cut / spurious left inside the input's conflictive sets (of those "
                  "present) / pairwise F1:", "",
                  "| method | " + " | ".join(f"({n})" for n in names) + " |",
                  "|---|" + "---|" * len(names)]
        for method in quality[0]:
            lines.append(f"| {method} | " + " | ".join(
                f"{q[method]['good_cut']} / {q[method]['spurious_cut']} / "
                f"{q[method]['spurious_left']} ({q[method]['spurious_in_sets']}) / "
                f"{q[method]['pairwise_f1']:.3f}" for q in quality) + " |")
    lines += ["", "Deleted links (good / spurious) per method:", "",
              "| method | " + " | ".join(f"({n})" for n in names) + " |",
              "|---|" + "---|" * len(names)]
    lines.append("| distributed (this) | " + " | ".join(
        f"{reports[n]['resolution']['deleted_links']} ({reports[n]['resolution']['good_deleted']}"
        f" / {reports[n]['resolution']['spurious_deleted']})" for n in names) + " |")
    for bl in reports[names[0]].get("baselines", {}):
        lines.append(f"| {bl} | " + " | ".join(
            f"{reports[n]['baselines'][bl]['deleted_links']} "
            f"({reports[n]['baselines'][bl]['good_deleted']} / "
            f"{reports[n]['baselines'][bl]['spurious_deleted']})" for n in names) + " |")
    return "\n".join(lines) + "\n"


SUMMARY_FILES = ("formations.md", "formations.json")
#: the last line of formations.md: digests of both summaries as written (module notes)
_PROOF = "<!-- written by formation-match run-formations: {md} {json} -->\n"
#: largest summary file read to check it
_MAX_SUMMARY_BYTES = 64 * 2**20


def _digest(text: str) -> str:
    import hashlib

    return hashlib.blake2b(text.encode("utf-8"), digest_size=16,
                           key=b"formation-match: run-formations summary").hexdigest()


def _written_by_us(parent: Path) -> set[str]:
    """The summary files of ``parent`` that a previous ``run-formations`` wrote and nobody
    changed since: ``formations.md`` ends with a line holding the digests of its own text
    and of ``formations.json`` as they were written."""
    from pipeline.outputs import read_small_text

    md = read_small_text(parent / "formations.md", _MAX_SUMMARY_BYTES)
    if md is None or not md.endswith("-->\n"):
        return set()
    body, _, last = md[:-1].rpartition("\n")
    body += "\n"
    ours = set()
    text = read_small_text(parent / "formations.json", _MAX_SUMMARY_BYTES)
    if text is not None and last == _PROOF.format(md=_digest(body), json=_digest(text))[:-1]:
        ours.add("formations.json")
    parts = last.split()
    if len(parts) == 8 and last == _PROOF.format(md=_digest(body), json=parts[6])[:-1]:
        ours.add("formations.md")
    return ours


def write_summaries(parent: Path, markdown: str, reports: dict) -> tuple[Path, Path]:
    """Write ``formations.md`` (``markdown`` and the proof line) and ``formations.json``
    (``reports``) into ``parent``, both put in place together."""
    from pipeline.runfolder import OutputFiles

    text = json.dumps(reports, indent=2) + "\n"
    md, js = parent / "formations.md", parent / "formations.json"
    with OutputFiles(replace=True) as outputs:
        outputs.path(md, "--out").write_text(
            markdown + _PROOF.format(md=_digest(markdown), json=_digest(text)), encoding="utf-8")
        outputs.path(js, "--out").write_text(text, encoding="utf-8")
    return md, js


def check_outputs(parent: Path, overwrite: bool) -> None:
    """Refuse, before any formation runs, an ``--out`` that is not a folder, a formation run
    folder that may not be replaced (:func:`pipeline.outputs.check_run_folder`) and a summary
    file that is a link, a special file, or a file run-formations did not write (unless
    ``overwrite``)."""
    from pipeline.errors import InputError
    from pipeline.outputs import RUN_MARKER, check_run_folder, refuse_unsafe_target

    if parent.exists() and not parent.is_dir():
        raise InputError(f"--out {str(parent)!r} is a file; run-formations writes a folder of "
                         "runs: give a folder name, e.g. runs")
    if os.path.lexists(parent / RUN_MARKER):
        raise InputError(f"--out {str(parent)!r} is a run folder; run-formations writes a "
                         "folder of four runs and its summaries, which would mix with that "
                         "run: choose another --out, e.g. runs")
    for name in FORMATIONS:
        check_run_folder(parent / f"formation-{name}", flag="--out")
    ours = _written_by_us(parent)
    for file_name in SUMMARY_FILES:
        path = parent / file_name
        refuse_unsafe_target(path, "--out")
        if path.exists() and not overwrite and file_name not in ours:
            raise InputError(f"--out {str(parent)!r} holds {file_name}, which run-formations "
                             "did not write; pass --overwrite to replace it, or choose another "
                             "--out")


def run(args) -> int:
    from pipeline import validate
    from pipeline.budget import check_formation_memory
    from pipeline.outcome import exit_status
    from pipeline.runfolder import claim_run_folder, publish_together
    from pipeline.runs.formation import FormationConfig, run_formation
    from pipeline.stages import check_merge_radius, merge_radius_for

    validate.not_empty(args.out, "--out", "give a folder name, e.g. runs")  # not the cwd
    method, max_features = feature_options(args)
    args.seed = validate.seed(args.seed, "--seed")
    resolution = args.resolution
    size = parse_size(args.size)
    merge_radius_for(resolution, args.merge_radius)  # before the first render
    check_merge_radius(args.merge_radius, [size], f"--size {args.size}")
    check_formation_memory(6, size, args.max_memory_gb, robots_option=False)  # one formation of 6 at a time
    parent = Path(args.out)
    check_outputs(parent, args.overwrite)
    reports = {}
    # every run folder is held from the start (as run-formation holds its --out): one that
    # another run is writing is refused before any formation runs, not after some did
    with contextlib.ExitStack() as claims:
        for name in FORMATIONS:
            claims.enter_context(claim_run_folder(parent / f"formation-{name}"))
        # the four run folders and the summaries are put in place together at the end: an error
        # or an interrupt before leaves the previous runs of --out as they were
        with publish_together() as together:
            for name in FORMATIONS:
                cfg = FormationConfig(formation=name, seed=args.seed, size=size,
                                      features=method, max_features=max_features,
                                      out=str(parent / f"formation-{name}"),
                                      resolution=resolution, merge_radius=args.merge_radius)
                out = together.staged_folder(run_formation(cfg, transport=args.transport))
                reports[name] = json.loads((out / "report.json").read_text())
            table = formations_table(reports)
            check_outputs(parent, args.overwrite)  # nothing of a user's came there meanwhile
            written = []
            # every option that changes the counts, the merge radius as the runs used it
            budget = "auto" if max_features is None else max_features
            radius = merge_radius_for(resolution, args.merge_radius)
            together.then(lambda: written.extend(write_summaries(
                parent, f"# Formations (a)–(d), seed {args.seed}, {method} ({budget} features per "
                f"image), {args.size}, resolution {args.resolution}, keypoint merge radius "
                f"{radius:g} px\n\n" + table, reports)))
    md, js = written
    print(table)
    print(f"saved {md} and {js}")
    # each formation's warnings about its result (no links, not conflict-free, ...), as
    # run-formation prints them; exit 3 when any result is not conflict-free
    status = 0
    for name, report in reports.items():
        flagged = io.StringIO()
        status = max(status, exit_status(report, flagged))
        for line in flagged.getvalue().splitlines():
            kind, _, message = line.partition(": ")
            print(f"{kind}: formation {name}: {message}", file=sys.stderr)
    return status
