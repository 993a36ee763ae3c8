"""The ``clean-h5`` job (:mod:`pipeline.commands.clean_h5` parses its options): hloc's
``features.h5`` / ``matches.h5`` in, a cleaned ``matches.h5`` out.

For hloc users: the matches of hloc's ``matches.h5`` are made consistent by the distributed
consistency stage (Aragüés et al., Sec. III detection and Sec. IV Alg. 1 resolution, one robot
per image), and a NEW ``matches.h5`` is written in hloc's format with the cut matches removed
(``matches0 = -1``), ready for ``hloc.reconstruction.main(..., matches=OUT.h5)``. The file
layout is described in :mod:`pipeline.inputs.hloc`.

The communication graph is the list of image pairs: ``--pairs pairs.txt`` (hloc's pairs file;
only those pairs are read), else every pair stored in ``matches.h5``. Before the distributed
stage, matches the paper's model cannot hold are cut with reason ``not-one-to-one`` (a
keypoint matched twice into the same other image, Assumption 2.2). Beside OUT.h5 it writes
``OUT.links.csv`` and ``OUT.rrd`` (:mod:`pipeline.runs.cleaned`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.budget import DEFAULT_LIMIT_GB
from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION, get_rule

__all__ = ["clean_h5"]


def clean_h5(features: str | Path, matches: str | Path, out: str | Path,
             pairs: str | Path | None = None, *, rerun: bool = True,
             image_dir: str | Path | None = None, outputs=None,
             max_memory_gb: float = DEFAULT_LIMIT_GB, baselines: bool = False,
             resolution: str = DEFAULT_LINKS_RESOLUTION, transport: str = "sim") -> dict:
    """Read hloc's files, make the matches consistent, write OUT.h5 and its side outputs.

    ``resolution``: the rule (:mod:`pipeline.consistency.rules`; default
    ``DEFAULT_LINKS_RESOLUTION``, the evidence of a match its hloc score as its quality);
    ``transport``: where its robots run (:mod:`pipeline.runs.transports`; over ``zenoh`` one
    process per image, each reading its own rows of the matches).

    ``baselines``: also run the centralized baselines on the matches the rule ran on (the
    summary's ``baselines``: :func:`pipeline.evaluation.report.baselines_beside`).

    Memory: what the files declare and what the detection needs are counted against
    ``max_memory_gb`` before they are allocated (:mod:`pipeline.budget`).

    ``outputs``: a :class:`pipeline.runfolder.OutputFiles` that puts every output in place
    together (default: each written at once).

    Returns
    -------
    dict — the summary printed by the command (counts before/after, links cut by reason,
    resolution figures, files written)

    Raises
    ------
    InputError
        Bad input files (see :func:`pipeline.inputs.hloc.read_h5`), ``out`` equal to the matches file
        (the command checks every output against every input first,
        :func:`pipeline.outputs.check_output_files`).
    """
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.budget import MemoryBudget, baselines_bytes, check_detection_memory
    from pipeline.commgraph import comm_edges_for
    from pipeline.consistency.setlists import bundle_budget
    from pipeline.inputs import hloc
    from pipeline.runfolder import output_path
    from pipeline.runs.cleaned import (
        CleaningOutcome,
        check_image_dir,
        cleaning_ledger,
        write_side_outputs,
    )
    from pipeline.runs.transports import check_team_size, resolve_alone

    out = Path(out)
    budget = MemoryBudget(max_memory_gb)
    contents = hloc.read_h5(features, matches, pairs, budget)
    links, m, n = contents.links, contents.features_per_camera, len(contents.names)
    sizes = _sizes(features, contents, image_dir)
    if rerun:
        check_image_dir(image_dir, contents.names, sizes, "hloc's image_size in the features file",
                        oriented=True)
    cam = {name: k for k, name in enumerate(contents.names)}
    # the pairs file (its repeated lines merged, as a graph file's) or, without one, the
    # images that share a match; checked as every comm graph is (pipeline.commgraph)
    pair_edges = None if pairs is None else \
        [[cam[a], cam[b]] for a, b in hloc.read_pairs(pairs, set(contents.names))]
    edges = comm_edges_for(m, links, pair_edges)
    reason = np.full(len(links), "", dtype=object)
    reason[contents.not_one_to_one] = "not-one-to-one"
    ok = reason == ""
    model_links = links.subset(ok)
    check_team_size(transport, n, "images in the features file")
    rule = get_rule(resolution)
    check_detection_memory(m, model_links, budget, detection=rule.detection,
                           set_lists=bundle_budget(len(m)) if rule.set_lists else None,
                           camera_sets=rule.camera_sets, in_flight=transport != "sim")
    if baselines:
        budget.add("the centralized baselines (--baselines)",
                   baselines_bytes(m, model_links), "drop --baselines")
    before = count_conflicts(AssociationGraph(m, model_links)).as_dict()
    result = resolve_alone(transport, m, edges, model_links, rule.name, contents.names,
                           "clean-h5")
    idx = np.flatnonzero(ok)
    reason[idx[result.deleted]] = "resolution"
    keep = reason == ""
    after = count_conflicts(AssociationGraph(m, links.subset(keep))).as_dict()
    hloc.write_cleaned_matches(contents, output_path(outputs, out, "--out"), keep)
    cut = {k: int((reason == k).sum()) for k in ("not-one-to-one", "resolution")}
    md = (f"## clean-h5 {Path(matches).name}\n\n| | before | after |\n|---|---:|---:|\n"
          f"| Matches | {len(links)} | {int(keep.sum())} |\n"
          f"| Conflictive sets | {before['conflictive_sets']} | {after['conflictive_sets']} |\n"
          f"| Cut not one-to-one | | {cut['not-one-to-one']} |\n"
          f"| Cut by resolution | | {cut['resolution']} |\n")
    outcome = CleaningOutcome(
        names=contents.names, sizes=sizes,
        keypoints=contents.keypoints,
        ledger=cleaning_ledger(links, reason, idx, result, model_links, m))
    written = write_side_outputs(outcome, out, rerun=rerun, image_dir=image_dir,
                                 report_markdown=md, outputs=outputs, oriented=True)
    st = result.stats
    summary = {"features": str(features), "matches": str(matches), "output": str(out),
               "written": [str(out)] + [str(p) for p in written], "images": n,
               "comm_edges": int(len(edges)), "links": int(len(links)), "before": before,
               "after": after, "cut": cut,
               "resolution": {**{k: st.get(k) for k in ("resolution", "iterations",
                                                       "detection_rounds", "resolution_rounds",
                                                       "messages", "bytes")},
                              "transport": transport,
                              **({"team": st["team"]} if "team" in st else {})}}
    from pipeline.evaluation.quality import quality_evidence

    # the rule weighs matching_scores0 as the links' quality: a distance (higher = worse) or a
    # score on another scale than [0, 1] is warned of, as resolve warns of its quality column
    summary["resolution_method"] = st.get("resolution")
    summary["quality_evidence"] = {**quality_evidence(m, model_links),
                                   "read_by_rule": bool(get_rule(st.get("resolution")
                                                                 or rule.name).needs_evidence)}
    if baselines:
        from pipeline.evaluation.report import baselines_beside

        summary["baselines"] = baselines_beside(m, model_links, ~result.deleted)
    return summary


def _sizes(features, contents, image_dir) -> list[tuple[int, int]]:
    """The size of each image whose pixels its keypoints are in: hloc's ``image_size`` where
    features.h5 stores it (the recording scales the keypoints to the images of ``image_dir``
    when these are of another size), else, with ``image_dir``, ``(0, 0)``: unknown, the
    keypoints are drawn as they are on that folder's image (hloc's keypoints are in the
    pixels of the image it read), and without it a canvas that holds every keypoint."""
    from pipeline.inputs import hloc

    stored = hloc.read_image_sizes(features)
    return [stored.get(name) or ((0, 0) if image_dir is not None else _size_of(kp))
            for name, kp in zip(contents.names, contents.keypoints, strict=True)]


#: largest side of a gray canvas drawn for an image (keypoints beyond it are off the canvas)
MAX_CANVAS_SIDE = 8192


def _size_of(keypoints: np.ndarray) -> tuple[int, int]:
    """A canvas that holds every keypoint (hloc's features.h5 may omit ``image_size``), at most
    :data:`MAX_CANVAS_SIDE` on a side."""
    if len(keypoints) == 0:
        return (64, 64)
    w, h = np.clip(np.ceil(keypoints.max(axis=0) + 1), 16, MAX_CANVAS_SIDE).astype(int)
    return (int(w), int(h))


