"""The ``clean-db`` job (:mod:`pipeline.commands.clean_db` parses its options): a COLMAP
database in, a cleaned copy out.

For COLMAP and hloc users: the verified matches of a database (its two-view geometries) are
made consistent by the distributed consistency stage (Aragüés et al., Sec. III detection and
Sec. IV Alg. 1 resolution, one robot per image), and a NEW database is written with the cut
links removed from the two-view geometries. Run COLMAP's mapper on OUT.db as usual.

Beside OUT.db it writes ``OUT.links.csv`` (every verified link, kept or deleted with its reason)
and ``OUT.rrd`` (:mod:`pipeline.runs.cleaned`). Before the distributed stage, links the paper's
model cannot hold are cut too, each with its reason: ``not-one-to-one`` (a feature linked twice or more into the same other image, Assumption 2.2;
every inlier of that feature into that image is cut: the database stores no score to tell
which is right. Measured on six Sceaux photos at 480 px, SIFT matched with cross-check off,
``OUT.db`` mapped by ``pycolmap.incremental_mapping`` with seeds 0-2: the input 6/6 images
registered, about 1,800 points at 0.38 px; keeping the first inlier of each feature, the
earlier rule, 5/6 and about 796 points at 0.90-0.94 px; cutting them all, 6/6 and about
1,550 points at 0.31 px) and, with ``--comm-graph``, ``not-comm-edge`` (a link
between images that are not neighbours: those robots could not have matched).

With ``loop_tol_deg`` (``--loop-check``) a pair-level pass runs first: the image pairs whose
relative rotation breaks the rotation loops of the view graph
(:func:`pipeline.matching.loops.loop_check`, a centralized pre-pass) lose all their links,
reason ``loop-inconsistent``. It finds what the consistency stage cannot see: a wrong
two-view geometry between two images of repeated structure, consistent at the level of
features.

With ``fusion`` (``--fusion``) the robust distributed fusion of Montijano et al. (dynamic
voting, :func:`pipeline.stages.fusion_stage`, the second stage of ``run-images``) runs after
the consistency stage, on the poses of a COLMAP mapping of the links the robots start from
(the input's, less those the checks above cut;
:func:`pipeline.colmap.incremental_mapping_with_retry`, seed 0, as ``run-images`` maps its
links before cleaning): the observations it votes out of their tracks leave them, their links
to the track's observations not voted out cut with reason ``fusion-outlier`` (a link between
two outliers stays where the two can be one point: :mod:`pipeline.fusion.landmarks`,
"Outliers leave the landmark"). It sees what the consistency stage cannot: a wrong match in a
conflict-free set (a window matched to its twin in several views), which only geometry with
poses refutes. The images the mapping did not register take no part (their links stay as the
consistency stage left them), as in ``run-images``. A mapping folded by the repeated structure
gives wrong poses, and fusion then cuts right links: the summary's ``fusion`` section gives
the mapping's figures, so a user can judge it.

With ``ignore_watermarks`` (``--ignore-watermarks``) the database is read as COLMAP's mapper
reads it with its ``ignore_watermarks`` option on (off by default): the two-view geometries of
configuration ``WATERMARK`` are left out, and only those (COLMAP's
``src/colmap/scene/database_cache.cc``, where the mapper's correspondence graph is built: a
pair is used when ``!ignore_watermarks || config != TwoViewGeometry::WATERMARK``; ``DEGENERATE``
and ``UNDEFINED`` pairs are used either way). Those pairs give no links to the stage and are
copied into ``OUT.db`` exactly as they were; ``--fusion``'s mapping ignores them too. The
summary's ``ignored_watermark_pairs`` counts them. Without it every pair with inliers gives
links, whatever its configuration, as the mapper's default reads them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.budget import DEFAULT_LIMIT_GB
from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION
from pipeline.errors import InputError

__all__ = ["CleanDbResult", "clean_database", "check_loop_tol", "check_no_log_beside",
           "COLMAP_MAX_ERROR_PX"]

#: COLMAP's default two-view verification threshold (``max_error``, pixels)
COLMAP_MAX_ERROR_PX = 4.0


@dataclass
class CleanDbResult:
    """What ``clean-db`` did; ``summary()`` is printed and can be saved as JSON."""

    input: Path
    output: Path
    images: int
    comm_edges: int
    links: int
    before: dict
    after: dict
    cut: dict
    resolution: dict = field(default_factory=dict)
    baselines: dict = field(default_factory=dict)
    loop_check: dict = field(default_factory=dict)
    fusion: dict = field(default_factory=dict)
    #: WATERMARK pairs left out (``--ignore-watermarks``); None: every pair was read
    ignored_watermark_pairs: int | None = None

    def summary(self) -> dict:
        out = {"input": str(self.input), "output": str(self.output), "images": self.images,
               "comm_edges": self.comm_edges, "links": self.links, "before": self.before,
               "after": self.after, "cut": self.cut, "resolution": self.resolution}
        if self.ignored_watermark_pairs is not None:
            out["ignored_watermark_pairs"] = self.ignored_watermark_pairs
        if self.baselines:
            out["baselines"] = self.baselines
        if self.loop_check:
            out["loop_check"] = self.loop_check
        if self.fusion:
            out["fusion"] = self.fusion
        return out


def clean_database(database: str | Path, out: str | Path,
                   comm_graph_file: str | Path | None = None,
                   max_memory_gb: float = DEFAULT_LIMIT_GB,
                   resolution: str = DEFAULT_LINKS_RESOLUTION, *, rerun: bool = True,
                   image_dir: str | Path | None = None, outputs=None,
                   baselines: bool = False, loop_tol_deg: float | None = None,
                   fusion: bool = False, ignore_watermarks: bool = False,
                   transport: str = "sim") -> CleanDbResult:
    """Read, make consistent, write a new database (see the module docstring).

    With ``resolution="evidence"`` a link's evidence is its Sampson error under the pair's
    stored fundamental matrix (:func:`pipeline.matching.link_evidence.geometric_llr`, ``T`` =
    :data:`COLMAP_MAX_ERROR_PX`) plus the triangle support the robots compute; a database
    holds no Lowe ratios.

    Parameters
    ----------
    database : input COLMAP database
    out : output database (must differ from the input)
    comm_graph_file : optional comm-graph file (:func:`pipeline.commgraph.read_comm_graph`)
    rerun : also write ``OUT.rrd`` beside ``out`` (``OUT.links.csv`` is always written;
        :mod:`pipeline.runs.cleaned`)
    image_dir : the images, drawn in the recording
    outputs : a :class:`pipeline.runfolder.OutputFiles` that puts every output in place
        together (default: each written at once)
    baselines : also run the centralized baselines on the links the rule ran on
        (``CleanDbResult.baselines``: :func:`pipeline.evaluation.report.baselines_beside`)
    loop_tol_deg : run the pair-level loop check first with this cycle tolerance (degrees;
        ``None``: not run): :func:`pipeline.matching.loops.loop_check` on the pairs with links
        left after the checks above, weighted by their inlier counts; its summary is
        ``CleanDbResult.loop_check``
    fusion : after the consistency stage, fuse the kept links' tracks on the poses of a COLMAP
        mapping of the input and cut the links of the observations voted out (module
        docstring); its summary is ``CleanDbResult.fusion``
    ignore_watermarks : read the database as COLMAP's mapper with ``ignore_watermarks`` on:
        its ``WATERMARK`` pairs (only those) give no links and are copied unchanged (module
        docstring); their number is ``CleanDbResult.ignored_watermark_pairs``
    transport : where the robots of the consistency stage run (:mod:`pipeline.runs.
        transports`): over ``zenoh`` one process per image, each given its own rows of the
        links, their weights and its keypoints; the fusion pass runs in the simulator only

    Returns
    -------
    CleanDbResult

    Raises
    ------
    InputError
        Missing/unreadable database, a database without two-view geometries, ``out`` equal to
        the input, a bad comm-graph file, a loop tolerance outside (0, 180) degrees.
    """
    from pipeline import colmap
    from pipeline.budget import BYTES_PER_CAMERA, BYTES_PER_ROW, COPIES_OF_READ_DATA, MemoryBudget

    database, out = Path(database), Path(out)
    if fusion and transport != "sim":
        raise InputError(f"--fusion runs on the simulated network only (its poses come from a "
                         f"COLMAP mapping of the whole database); drop --transport {transport} "
                         "or --fusion")
    if loop_tol_deg is not None:
        check_loop_tol(loop_tol_deg)
    if os.path.realpath(out) == os.path.realpath(database):  # a loop is named below
        raise InputError(f"--out {str(out)!r} is the input database; the input is never "
                         f"modified, choose a new file")
    check_no_log_beside(out)
    # every allocation that grows with the input is counted before it is made
    budget = MemoryBudget(max_memory_gb)

    def count_tables(sizes) -> None:
        budget.add("the keypoints and verified matches of the database",
                   sizes["keypoint_bytes"] * COPIES_OF_READ_DATA
                   + sizes["inliers"] * BYTES_PER_ROW)
        budget.add(f"the robots of its {sizes['images']} images",
                   sizes["images"] * BYTES_PER_CAMERA)

    contents = colmap.read_database(database, check_sizes=count_tables,
                                    ignore_watermarks=ignore_watermarks)
    try:
        result = _clean(contents, database, out, comm_graph_file, budget, resolution, rerun,
                        image_dir, outputs, baselines, loop_tol_deg, fusion, ignore_watermarks,
                        transport)
        if ignore_watermarks:
            result.ignored_watermark_pairs = contents.watermark_pairs_ignored
        return result
    finally:
        contents.close()


def _warn_split(n: int, links, off_graph: np.ndarray) -> None:
    """Warn when ``--comm-graph`` leaves the images in more groups than the database's verified
    matches do: the links between the groups are cut (``not-comm-edge``), their features are
    never associated, and COLMAP's mapper on OUT.db holds one group per model at best."""
    import logging

    from pipeline.commgraph import graph_parts, split_warning

    def pairs(mask):
        return np.stack([links.cam_i[mask], links.cam_j[mask]], axis=1)

    joined = graph_parts(n, pairs(np.ones(len(links), dtype=bool)))
    parts = graph_parts(n, pairs(~off_graph))
    if parts > joined:
        logging.getLogger(__name__).warning("warning: %s", split_warning(
            n, pairs(~off_graph), parts=parts, advice=(
                f"the database's verified matches join them in {joined}; add the missing "
                "edges to --comm-graph, or leave it out")))


def _clean(contents, database: Path, out: Path, comm_graph_file, budget, resolution: str,
           rerun: bool, image_dir, outputs, baselines: bool = False,
           loop_tol_deg: float | None = None, fusion: bool = False,
           ignore_watermarks: bool = False, transport: str = "sim") -> CleanDbResult:
    """:func:`clean_database` on the database read as ``contents``."""
    from pipeline import colmap
    from pipeline.association import AssociationGraph, count_conflicts
    from pipeline.budget import BYTES_PER_EDGE, baselines_bytes, check_detection_memory, count_lines
    from pipeline.commgraph import links_off_graph, read_comm_graph
    from pipeline.consistency.rules import get_rule
    from pipeline.consistency.setlists import bundle_budget
    from pipeline.outputs import require_input_file
    from pipeline.runfolder import output_path
    from pipeline.runs.cleaned import check_image_dir
    from pipeline.runs.transports import check_team_size, resolve_alone

    links, m, n = contents.links, contents.features_per_camera, len(contents.names)
    check_team_size(transport, n, "images in the database")
    if rerun:
        check_image_dir(image_dir, contents.names, _camera_sizes(contents),
                        "the camera of the database")
    reason = np.full(len(links), "", dtype=object)
    reason[contents.not_one_to_one] = "not-one-to-one"
    if comm_graph_file is not None:
        budget.add("the communication graph", count_lines(
            require_input_file(comm_graph_file, "--comm-graph")) * BYTES_PER_EDGE)
        edges = read_comm_graph(comm_graph_file, contents.names)
        off_graph = links_off_graph(links, edges, n)
        reason[off_graph & (reason == "")] = "not-comm-edge"
        _warn_split(n, links, off_graph)
    else:
        edges = None
    loop_section = {}
    if loop_tol_deg is not None:
        loop_section = _loop_pass(contents, reason, loop_tol_deg)
    model_ok = reason == ""
    model_links = links.subset(model_ok)
    # the association graph the robots start from: one-to-one links on comm edges
    rule = get_rule(resolution)
    check_detection_memory(m, model_links, budget, detection=rule.detection,
                           set_lists=bundle_budget(len(m)) if rule.set_lists else None,
                           camera_sets=rule.camera_sets, in_flight=transport != "sim")
    if baselines:
        budget.add("the centralized baselines (--baselines)",
                   baselines_bytes(m, model_links), "drop --baselines")
    before = count_conflicts(AssociationGraph(m, model_links)).as_dict()
    evidence = dict(link_weight=_link_weight(contents, model_links),
                    keypoints=contents.keypoints) if rule.needs_evidence else None
    # the stage shows its own round counter on a long run (pipeline.progress.rounds_bar)
    result = resolve_alone(transport, m, edges, model_links, resolution, contents.names,
                           "clean-db", evidence=evidence)
    idx = np.flatnonzero(model_ok)
    reason[idx[result.deleted]] = "resolution"
    fusion_section = _fusion_pass(contents, model_ok, model_links, idx, result, reason,
                                  edges, ignore_watermarks) if fusion else {}
    keep = reason == ""
    after = count_conflicts(AssociationGraph(m, links.subset(keep))).as_dict()
    colmap.write_cleaned_database(contents, output_path(outputs, out, "--out"), keep)
    _side_outputs(contents, links, reason, idx, result, model_links, m, out, rerun, image_dir,
                  before, after, outputs)
    n_edges = len(edges) if edges is not None else \
        len(np.unique(model_links.cam_i * n + model_links.cam_j))
    stats = result.stats
    section = {}
    if baselines:
        from pipeline.evaluation.report import baselines_beside

        section = baselines_beside(m, model_links, ~result.deleted)
    return CleanDbResult(
        input=database, output=out, images=n, comm_edges=n_edges, links=len(links),
        before=before, after=after,
        cut={k: int((reason == k).sum()) for k in ("not-one-to-one", "not-comm-edge")
             + (("loop-inconsistent",) if loop_tol_deg is not None else ()) + ("resolution",)
             + (("fusion-outlier",) if fusion else ())},
        resolution={"method": stats.get("resolution"), **{k: stats.get(k) for k in (
            "iterations", "detection_rounds", "resolution_rounds", "messages", "bytes",
            "max_robot_memory_bytes")}, "transport": transport,
            **({"team": stats["team"]} if "team" in stats else {})},
        baselines=section, loop_check=loop_section,
        fusion=fusion_section)


def check_no_log_beside(out: Path) -> None:
    """InputError when SQLite's write-ahead log or rollback journal of a database named
    ``out`` lies beside it (the database is open in another program, e.g. COLMAP, or was not
    closed): SQLite would replay it into the new database written there, e.g. a COLMAP
    session's edits into the cleaned copy, or every two-view geometry deleted."""
    for side in ("-wal", "-journal"):
        log = Path(f"{out}{side}")
        if os.path.lexists(log):
            raise InputError(
                f"--out {str(out)!r}: {str(log)!r} beside it holds changes of a database of that "
                f"name not yet written into it (a program, e.g. COLMAP, has it open or did not "
                f"close it); SQLite would apply them to the new database. Close that program, "
                f"or choose another --out")


def check_loop_tol(tol_deg) -> float:
    """``--loop-tol`` as a float, or InputError naming it (an angle in (0, 180) degrees)."""
    from pipeline.matching.loops import DEFAULT_LOOP_TOL_DEG

    try:
        tol = float(tol_deg)
    except (TypeError, ValueError):
        tol = float("nan")
    if not (np.isfinite(tol) and 0.0 < tol < 180.0):
        raise InputError(f"--loop-tol {tol_deg!r}: the cycle tolerance is an angle in degrees "
                         f"between 0 and 180 (default {DEFAULT_LOOP_TOL_DEG:g})")
    return tol


def _loop_pass(contents, reason: np.ndarray, tol_deg: float) -> dict:
    """The pair-level loop check (:mod:`pipeline.matching.loops`) on the pairs that still have
    links; the links of the pairs it drops get ``reason`` ``loop-inconsistent`` (in place)."""
    from pipeline import colmap
    from pipeline.matching.loops import loop_check

    links, n = contents.links, len(contents.names)
    pairs, rotations, inliers = colmap.relative_rotations(contents)
    key = links.cam_i * n + links.cam_j
    live = np.isin(pairs[:, 0] * n + pairs[:, 1], key[reason == ""])
    check = loop_check(n, pairs[live], rotations[live], inliers[live], tol_deg)
    bad = pairs[live][check.inconsistent]
    reason[np.isin(key, bad[:, 0] * n + bad[:, 1]) & (reason == "")] = "loop-inconsistent"
    return {"tol_deg": float(tol_deg), **check.summary(),
            "links_cut": int((reason == "loop-inconsistent").sum())}


def _fusion_pass(contents, model_ok: np.ndarray, model_links, idx: np.ndarray, result,
                 reason: np.ndarray, edges, ignore_watermarks: bool = False) -> dict:
    """Fusion on the poses of a COLMAP mapping of the input (module docstring): the links it
    cuts among the consistency stage's kept ``model_links`` (rows ``idx`` of the database's
    links) get ``reason`` ``fusion-outlier`` (in place). The mapping sees the links the robots
    started from (``model_ok``: without those the checks before the stage cut, e.g. outside
    the comm graph). Returns the summary's ``fusion`` section."""
    from pipeline import colmap
    from pipeline.commgraph import comm_edges_for
    from pipeline.runfolder import scratch_folder
    from pipeline.stages import fusion_on_reconstruction, ledger_from_consistency
    from pipeline.types import Features, View

    with scratch_folder("clean-db-mapping-") as tmp:
        # the snapshot is what was read: the mapping sees the same matches, the input stays
        # untouched; a copy without the links cut before the stage when there are any
        db = contents.snapshot or contents.path
        if not model_ok.all():
            db = colmap.write_cleaned_database(contents, Path(tmp) / "model.db", model_ok)
        mapping = colmap.incremental_mapping_with_retry(
            db, seed=0, **({"ignore_watermarks": True} if ignore_watermarks else {}))
    names = contents.names
    # a database holds no pixels and no poses: fusion reads names, keypoints and the mapping
    views = [View(name, np.zeros((1, 1), np.uint8), np.eye(3)) for name in names]
    feats = [Features(kp, np.zeros((len(kp), 0), np.float32), np.ones(len(kp), np.float32),
                      "sift") for kp in contents.keypoints]
    ledger = ledger_from_consistency(result)
    fr, n_cut, reg = fusion_on_reconstruction(
        ledger, views, feats, comm_edges_for(contents.features_per_camera, model_links, edges),
        mapping.reconstruction)
    registered = {names[k] for k in reg.tolist()}
    section = {"enabled": fr is not None, "poses_from": "COLMAP mapping of the input "
               "database (seed 0)", "mapping": {k: v for k, v in mapping.summary().items()
                                                if k != "registered_names"},
               "cameras": int(len(reg)),
               "cameras_without_pose": [n for n in names if n not in registered]}
    if fr is None:
        section["reason"] = (f"camera poses unknown: the mapping registered {len(reg)} of "
                             f"{len(names)} images")
        return section
    reason[idx[ledger.reason == "fusion-outlier"]] = "fusion-outlier"
    section.update({k: v for k, v in dict(fr.stats).items() if np.isscalar(v)},
                   links_cut=int(n_cut))
    return section


def _link_weight(contents, links) -> np.ndarray:
    """Geometric log-likelihood ratio of each link from the pair's stored ``F``, ``(L,)``."""
    from pipeline.matching.link_evidence import geometric_llr
    from pipeline.matching.pairs import sampson_error_px

    err = np.full(len(links), np.nan)
    n = len(contents.names)
    pair = links.cam_i * n + links.cam_j
    for key in np.unique(pair).tolist():
        i, j = divmod(key, n)
        F = contents.fundamental.get((i, j))
        if F is None:
            continue
        sel = pair == key
        err[sel] = sampson_error_px(F, contents.keypoints[i][links.feat_i[sel]],
                                    contents.keypoints[j][links.feat_j[sel]])
    return geometric_llr(err, pair, COLMAP_MAX_ERROR_PX)


def _camera_sizes(contents) -> list[tuple[int, int]]:
    """``(width, height)`` of each image's camera, ``(0, 0)`` where it has none."""
    return [(int(c.width), int(c.height)) if c is not None else (0, 0)
            for c in contents.cameras]


def _side_outputs(contents, links, reason, idx, result, model_links, m, out, rerun, image_dir,
                  before, after, outputs) -> None:
    """``OUT.links.csv`` and ``OUT.rrd`` beside the cleaned database (:mod:`pipeline.runs.cleaned`)."""
    from pipeline.runs.cleaned import CleaningOutcome, cleaning_ledger, write_side_outputs

    sizes = _camera_sizes(contents)
    md = (f"## clean-db {Path(contents.path).name}\n\n| | before | after |\n|---|---:|---:|\n"
          f"| Verified links | {len(links)} | {int((reason == '').sum())} |\n"
          f"| Conflictive sets | {before['conflictive_sets']} | {after['conflictive_sets']} |\n")
    ledger = cleaning_ledger(links, reason, idx, result, model_links, m)
    write_side_outputs(CleaningOutcome(contents.names, sizes, contents.keypoints, ledger),
                       out, rerun=rerun, image_dir=image_dir, report_markdown=md,
                       outputs=outputs)


