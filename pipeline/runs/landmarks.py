"""The ``run-landmarks`` job (:mod:`pipeline.commands.run_landmarks` parses its options):
labelled-landmark benchmarks.

For folders where every image carries the same hand-labelled keypoints in the same order
(:mod:`pipeline.inputs.landmarks`; e.g. the CMU hotel sequence), so the true association is
known exactly: landmark ``k`` of one image is landmark ``k`` of every other.

Stages: load (keypoints and descriptors; ``--frames N`` takes ``N`` images at a fixed
stride) → each robot matches its landmarks to its communication neighbours' one-to-one
(Hungarian on the descriptor distance, guided by the epipolar geometry of the labelled
keypoints, optional ratio gate; :mod:`pipeline.matching.landmarks`)
→ ``--refine votes``: the robots refine those matches by two-hop votes through common
neighbours (:mod:`pipeline.matching.votes`) → the distributed consistency stage
(``--resolution``; with ``--transport zenoh`` one robot process per image, each reading its
own rows of the links, the transport's ``resolve`` job: a robot lost there stops the run)
→ the centralized baselines on the same links → evaluation.

Defaults (stated): guided matching at a 3 px epipolar threshold (hand-labelled positions,
:mod:`pipeline.matching.landmarks`), the
whole assignment kept (``--ratio none``), refined by votes only when the rule does not weigh
the cycles itself (:func:`default_refinement`: ``paper``, ``paper-labels``; ``sync`` and
``evidence`` take the matches as they are, see ``weighs_cycles`` in
:mod:`pipeline.consistency.rules`). The
votes are the ambiguity filter Alg. 1 needs: a pair the ratio gate would drop still carries paths
that vote for the right match, and gating before voting removes them.

Scoring follows CLEAR (Fathian et al., T-RO 2020): an association is judged by the pairwise
matches it implies, i.e. every two landmarks in one association set of the kept links (the
transitive closure), against the true pairs of *every* image pair (:mod:`pipeline.evaluation.metrics`).
``pairwise.input_links`` scores the Hungarian matches themselves, the way CLEAR scores its
input; ``before`` / ``before_links`` are the links the consistency stage receives (after the
refinement), over their closure and as they are. ``cycle_consistent`` is true when no association set holds two landmarks of one image
(then the implied pairwise matching is cycle-consistent).

Writes ``report.json`` and ``links.csv`` (docs/DESIGN.md "Run outputs"; ``truth`` is 1 when the
two ends carry the same label; a feature index of ``links.csv`` counts the landmarks its image
sees, ``feature_landmarks`` in ``report.json`` maps it to its label row) atomically. There are
no camera poses and no 3D points, so no ``sparse/`` and no recording.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from pipeline.budget import DEFAULT_LIMIT_GB
from pipeline.consistency.rules import DEFAULT_LINKS_RESOLUTION
from pipeline.errors import InputError, listed
from pipeline.outcome import flag_result
from pipeline.progress import StageTimer
from pipeline.runfolder import atomic_run_folder, write_json_atomic
from pipeline.types import Links

__all__ = ["LandmarksConfig", "REFINEMENTS", "default_refinement", "landmark_comm_graph",
           "run_landmarks", "true_landmark_pairs", "landmarks_markdown"]


#: refinements of the landmark matches before the consistency stage
REFINEMENTS = ("votes", "none")
#: why a labelled folder may give no link (the ``no-links`` warning of :mod:`pipeline.outcome`)
NO_LANDMARK_LINKS_WHY = ("a --ratio gate so strict that it keeps no match, or a --graph "
                         "without an edge")


def guidance_warning(matching: dict) -> str | None:
    """What to tell when ``--geometry epipolar`` guided no pair: every edge kept its plain
    descriptor assignment (fewer than 8 assigned landmarks, no fundamental matrix, or a
    homography explaining the assignment as well, as on a planar scene or a pure rotation:
    :func:`pipeline.matching.landmarks.guided_match`). The run then is a descriptors-only
    run under another name; None where some edge was guided."""
    edges = int(matching.get("edges", 0))
    if matching.get("geometry") != "epipolar" or edges == 0 \
            or int(matching.get("edges_without_model", 0)) < edges:
        return None
    return (f"--geometry epipolar guided none of the {edges} image pairs: no pair had a usable "
            "fundamental matrix (fewer than 8 matched landmarks, or a homography explains the "
            "matches as well: a planar scene, or a camera that only rotates), so every pair "
            "kept its descriptor assignment, as with --geometry none")

def default_refinement(resolution: str) -> str:
    """``--refine`` when not given: ``none`` for a rule that weighs the cycles of the links
    itself (``weighs_cycles``), ``votes`` for the others (module notes)."""
    from pipeline.consistency.rules import get_rule

    return "none" if get_rule(resolution).weighs_cycles else "votes"


@dataclass
class LandmarksConfig:
    """Options of ``run-landmarks`` (see ``python -m pipeline run-landmarks --help``)."""

    directory: str
    graph: str = "complete"
    frames: int | None = None
    descriptors: str = "auto"
    ratio: float | None = None
    geometry: str = "epipolar"
    epipolar_px: float = 3.0
    refine: str | None = None  # None: the rule's (default_refinement)
    vote_iterations: int = 10
    resolution: str = DEFAULT_LINKS_RESOLUTION
    baselines: bool = True
    out: str | None = None
    max_memory_gb: float = DEFAULT_LIMIT_GB
    transport: str = "sim"

    def out_dir(self) -> Path:
        if self.out:
            return Path(self.out)
        # realpath, not Path.resolve: a symbolic link that loops is named by the folder's check
        folder = Path(os.path.realpath(self.directory)).name or "landmarks"
        frames = f"-f{self.frames}" if self.frames else ""
        # a graph file by its stem, as run-images names it: its path would nest folders
        graph = Path(self.graph).stem if Path(self.graph).is_file() else self.graph.replace(":", "")
        return Path("runs") / f"landmarks-{folder}{frames}-{graph}"


def landmark_comm_graph(graph: str, names: list[str], folder_names: list[str],
                        frames: int | None) -> np.ndarray:
    """The communication graph over the images a run keeps, ``(E, 2)`` int64 in their order.

    A kind (``ring``, ``seq:K``, ...) is built over the kept images (``names``, in name
    order). A graph file gives images by name or by index in the folder's natural name order
    (``folder_names``: every labelled image of the folder, as ``run-images`` counts them), so
    one file means the same images with or without ``--frames``; with ``--frames N`` every
    edge must join two kept images (:func:`pipeline.inputs.landmarks.select_frames`), else
    InputError naming the edge and the image left out.
    """
    from pipeline.commgraph import comm_graph, names_graph_file
    from pipeline.inputs.landmarks import select_frames

    if len(folder_names) == len(names) or not names_graph_file(graph):
        return comm_graph(graph, names, offers_knn=False)
    edges = comm_graph(graph, folder_names, offers_knn=False)
    kept = select_frames(len(folder_names), frames)
    at = np.full(len(folder_names), -1, dtype=np.int64)
    at[kept] = np.arange(len(kept))
    off = (at[edges] < 0).any(axis=1)
    if off.any():
        i, j = (int(v) for v in edges[np.flatnonzero(off)[0]])
        gone = i if at[i] < 0 else j
        raise InputError(f"{graph}: the edge {folder_names[i]} - {folder_names[j]} (images {i} "
                         f"and {j} of the folder's {len(folder_names)}, in name order) joins "
                         f"{folder_names[gone]}, which --frames {frames} leaves out (it keeps "
                         f"images {listed(kept.tolist(), 8, last=', ')}); list edges between "
                         "kept images only, or drop --frames")
    return at[edges]


def _check_matching_memory(m, comm_edges, config: LandmarksConfig) -> None:
    """InputError before the matching when its largest image pair of the comm graph would
    need more than ``config.max_memory_gb`` (:data:`pipeline.budget.BYTES_PER_LANDMARK_PAIR`
    per landmark pair)."""
    from pipeline.budget import BYTES_PER_LANDMARK_PAIR, MemoryBudget, limit_gb

    edges = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
    if not len(edges):
        return
    k = np.argmax(m[edges[:, 0]] * m[edges[:, 1]])
    i, j = int(edges[k, 0]), int(edges[k, 1])
    MemoryBudget(limit_gb(config.max_memory_gb)).add(
        f"matching images {i} and {j} ({m[i]} x {m[j]} landmark pairs)",
        int(m[i]) * int(m[j]) * BYTES_PER_LANDMARK_PAIR, "match fewer landmarks per image")


def _check_memory(m, links: Links, config: LandmarksConfig) -> None:
    """The memory guard of :mod:`pipeline.budget` on the matched links, before the rule and
    the baselines allocate what grows with them: InputError naming the part above
    ``config.max_memory_gb`` (the detection of Sec. III, which the ``paper`` rule runs before
    Alg. 1, needs GBs on a dense graph of a hundred frames)."""
    from pipeline.budget import (
        MemoryBudget,
        baselines_bytes,
        check_detection_memory,
        limit_gb,
    )
    from pipeline.consistency.rules import get_rule
    from pipeline.consistency.setlists import bundle_budget

    budget = MemoryBudget(limit_gb(config.max_memory_gb))
    budget.add_rows("the matched links", len(links))
    rule = get_rule(config.resolution)
    check_detection_memory(m, links, budget, detection=rule.detection,
                           set_lists=bundle_budget(len(m)) if rule.set_lists else None,
                           camera_sets=rule.camera_sets, in_flight=config.transport != "sim")
    if config.baselines:
        budget.add("the centralized baselines", baselines_bytes(m, links),
                   "add --no-baselines")


def shared_descriptor_warning(frames) -> str | None:
    """A warning when landmarks of one image have identical descriptor rows (two labels
    within a pixel of each other, or copied rows): the assignment cannot tell them apart and
    settles its ties by row order, which is the labels' order in every image, so the scores
    would credit the labels, not the matching."""
    hits = []
    for f in frames:
        _, first, counts = np.unique(f.descriptors, axis=0, return_index=True,
                                     return_counts=True)
        if (counts > 1).any():
            dup = int(counts[counts > 1].sum())
            k = int(first[np.flatnonzero(counts > 1)[0]])
            same = np.flatnonzero((f.descriptors == f.descriptors[k]).all(axis=1))
            rows = [int(f.landmarks[j]) + 1 for j in same[:2]]
            hits.append(f"{f.name} ({dup} landmarks, e.g. label rows {rows[0]} and {rows[1]})")
    if not hits:
        return None
    return (f"{len(hits)} image(s) hold landmarks with identical descriptors: "
            f"{'; '.join(hits[:3])}{'; ...' if len(hits) > 3 else ''}; matching cannot tell "
            "them apart and breaks the tie by row order, the labels' order in every image, so the "
            "scores are optimistic; merge or remove landmarks labelled at the same spot")


def true_landmark_pairs(features_per_camera, landmarks=None) -> np.ndarray:
    """True pairs ``(Q, 2)`` (global ids) of every image pair: features of one landmark.

    ``landmarks``: per image, the landmark of each feature (``LandmarkFrame.landmarks``);
    ``None``: feature ``k`` is landmark ``k`` in every image (an image with fewer features
    contributes its rows ``0..K_i-1``).
    """
    m = np.asarray(features_per_camera, dtype=np.int64)
    if landmarks is None:
        landmarks = [np.arange(k) for k in m]
    off = np.concatenate([[0], np.cumsum(m)])
    parts = []
    for i in range(m.size):
        for j in range(i + 1, m.size):
            _, fi, fj = np.intersect1d(landmarks[i], landmarks[j], assume_unique=True,
                                       return_indices=True)
            parts.append(np.stack([off[i] + fi, off[j] + fj], axis=1))
    return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.int64)


def _scores(m, links: Links, true_pairs) -> dict:
    """Pairwise scores of the closure of ``links`` (``true_pairs``: a :class:`~pipeline.
    evaluation.metrics.PairwiseTruth`, or the ``(Q, 2)`` pairs), counted per association set
    without listing the ``k (k - 1) / 2`` pairs of each: a set chaining thousands of features
    implies billions of them."""
    from pipeline.evaluation.metrics import PairwiseTruth

    if not isinstance(true_pairs, PairwiseTruth):
        true_pairs = PairwiseTruth(true_pairs, int(np.sum(m)))
    return true_pairs.scores(m, links)


def _link_scores(m, links: Links, true_pairs: np.ndarray) -> dict:
    """The links themselves as the predicted pairs (how CLEAR scores its pairwise input)."""
    from pipeline.association import camera_offsets
    from pipeline.evaluation.metrics import pairwise_scores

    off = camera_offsets(m)
    pred = np.stack([off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j], axis=1)
    return pairwise_scores(pred, true_pairs, int(np.sum(m)))


def run_landmarks(config: LandmarksConfig, timer: StageTimer | None = None) -> tuple[Path, dict]:
    """Run every stage and write the run folder; return its path and the report.

    Raises
    ------
    InputError
        Bad folder or files (:func:`pipeline.inputs.landmarks.load_landmark_folder`), graph
        (:func:`pipeline.commgraph.comm_graph`), ratio or resolution method.
    """
    from pipeline.association import AssociationGraph, camera_offsets, count_conflicts
    from pipeline.commgraph import split_warning
    from pipeline.consistency import centralized
    from pipeline.consistency.rules import deleted_cases, get_rule, rule_names
    from pipeline.evaluation.metrics import PairwiseTruth
    from pipeline.evaluation.report import versions
    from pipeline.inputs.landmarks import folder_image_names, load_landmark_folder
    from pipeline.inputs.linkscsv import write_links_csv
    from pipeline.matching.landmarks import match_landmark_edges
    from pipeline.runs.transports import check_team_size, resolve_alone
    from pipeline.stages import ledger_from_consistency

    if config.refine is not None and config.refine not in REFINEMENTS:
        raise InputError(f"--refine {config.refine!r}: expected one of {', '.join(REFINEMENTS)}")
    if config.vote_iterations < 1:
        raise InputError(f"--vote-iterations {config.vote_iterations}: expected at least 1")
    if not 0 < config.epipolar_px < float("inf"):
        raise InputError(f"--epipolar-px {config.epipolar_px}: expected a positive, finite "
                         "number of pixels")
    if config.resolution not in rule_names():
        raise InputError(f"--resolution {config.resolution!r}: expected one of "
                         f"{', '.join(rule_names())}")
    if config.refine is None:
        config = replace(config, refine=default_refinement(config.resolution))
    timer = timer or StageTimer()
    out = config.out_dir()
    with timer.stage("load", f"{config.directory}, descriptors {config.descriptors}"):
        frames = load_landmark_folder(config.directory, config.descriptors, config.frames)
        names = [f.name for f in frames]
        comm_edges = landmark_comm_graph(config.graph, names,
                                         folder_image_names(config.directory), config.frames)
        m = np.array([len(f.keypoints) for f in frames], dtype=np.int64)
        kind = frames[0].descriptor_kind
        source = "sift" if frames[0].descriptor_file == "sift" else "given"
        # images with 'nan nan' rows see fewer landmarks: the first image's count is not all's
        seen = f"x {m[0]}" if (m == m[0]).all() else f"seeing {m.min()}-{m.max()}"
        timer.note(f"{len(frames)} images {seen} landmarks, {kind} descriptors ({source}); "
                   f"graph {config.graph}: {len(comm_edges)} edges")
        message = split_warning(len(frames), comm_edges, lost="their landmarks cannot be "
                                "associated across the groups")
        if message:
            timer.warn(message)
        message = shared_descriptor_warning(frames)
        if message:
            timer.warn(message)
    check_team_size(config.transport, len(frames), "images")
    _check_matching_memory(m, comm_edges, config)
    with timer.stage("matching", f"Hungarian ({'chi-square' if kind == 'histogram' else 'L2'}), "
                                 f"geometry {config.geometry}, ratio gate {config.ratio}"):
        links, matching = match_landmark_edges(
            [f.descriptors for f in frames], comm_edges, kind, config.ratio,
            [f.keypoints for f in frames], config.geometry, config.epipolar_px)
        timer.note(f"{len(links)} links; {matching['edges_without_model']} edges without an "
                   "epipolar model" if config.geometry == "epipolar" else f"{len(links)} links")
        message = guidance_warning(matching)
        if message:
            timer.warn(message)
    # times: wall (StageTimer) and CPU of this process (all simulated robots run in it, one
    # after another; a team would run them in parallel)
    refinement = {"method": config.refine}
    if config.refine == "votes":
        from pipeline.matching.votes import refine_by_votes

        input_links = links
        with timer.stage("refine", "two-hop votes through common neighbours"):
            c0 = time.process_time()
            links, vstats = refine_by_votes(m, comm_edges, links, config.vote_iterations)
            refinement.update(vstats, cpu_s=round(time.process_time() - c0, 4))
            timer.note(f"{len(links)} links after {vstats['iterations']} iteration(s); "
                       f"changed per iteration {vstats['changed_per_iteration']}")
    else:
        input_links = links
    _check_memory(m, links, config)
    with timer.stage("resolution", get_rule(config.resolution).title):
        c0 = time.process_time()
        res = resolve_alone(config.transport, m, comm_edges, links, config.resolution, names,
                            "run-landmarks")
        resolution_cpu = time.process_time() - c0
        kept = ~res.deleted
        timer.note(f"{int(res.deleted.sum())} links cut")
    kept_links = links.subset(kept)
    lid = [f.landmarks for f in frames]
    lid_all, off = np.concatenate(lid), camera_offsets(m)
    truth = lid_all[off[links.cam_i] + links.feat_i] == lid_all[off[links.cam_j] + links.feat_j]
    with timer.stage("evaluate", "pairwise scores over the closure of the links"):
        tp = true_landmark_pairs(m, lid)
        n_true_on_edges = int(sum(np.intersect1d(lid[i], lid[j]).size
                                  for i, j in comm_edges.tolist()))

        def counts(lk: Links, t: np.ndarray) -> dict:
            c = count_conflicts(AssociationGraph(m, lk)).as_dict()
            c.update(good_links=int(t.sum()), spurious_links=int((~t).sum()),
                     missing_links=n_true_on_edges - int(t.sum()),
                     precision=float(t.mean()) if len(t) else None)
            return c

        before, after = counts(links, truth), counts(kept_links, truth[kept])
        truth_pairs = PairwiseTruth(tp, int(np.sum(m)))
        pairwise = {"input_links": _link_scores(m, input_links, tp),
                    "before": _scores(m, links, truth_pairs),
                    "before_links": _link_scores(m, links, tp),
                    "after": _scores(m, kept_links, truth_pairs)}
    baselines = {}
    if config.baselines:
        with timer.stage("baselines", "centralized, same links"):
            for name, fn in centralized.BASELINES.items():
                t0 = time.perf_counter()
                keep = np.asarray(fn(m, links), dtype=bool)
                dt = time.perf_counter() - t0
                bl = links.subset(keep)
                baselines[name] = {"pairwise": _scores(m, bl, truth_pairs),
                                   "cycle_consistent": bool(centralized.is_conflict_free(m, bl)),
                                   "deleted_links": int((~keep).sum()),
                                   "good_deleted": int((~keep & truth).sum()),
                                   "spurious_deleted": int((~keep & ~truth).sum()),
                                   "time_s": round(dt, 4)}
    st = res.stats
    cut = res.deleted
    report = {
        "title": f"landmarks {Path(config.directory).resolve().name}, {len(frames)} images, "
                 f"graph {config.graph}",
        "n_cameras": len(frames),
        "comm_edges": comm_edges.tolist(),
        "features_per_camera": m.tolist(),
        "images": names,
        "before": before,
        "after": after,
        "pairwise": pairwise,
        "cycle_consistent": bool(after["conflictive_sets"] == 0),
        "cycle_consistent_before": bool(before["conflictive_sets"] == 0),
        "matching": {**matching, "descriptors": source},
        "refinement": refinement,
        "resolution": {
            "method": config.resolution,
            "iterations": st.get("iterations"),
            "deleted_links": int(cut.sum()),
            "good_deleted": int((cut & truth).sum()),
            "spurious_deleted": int((cut & ~truth).sum()),
            # Alg. 1's cases, then the rule's own (the cuts of sync and evidence counted too)
            "deleted_by_case": {c: int((res.case == c).sum())
                                for c in deleted_cases(st.get("resolution", config.resolution))},
            "detection_rounds": st.get("detection_rounds"),
            "resolution_rounds": st.get("resolution_rounds"),
            "messages": st.get("messages"),
            "bytes": st.get("bytes"),
            "max_robot_memory_bytes": st.get("max_robot_memory_bytes"),
            "time_s": round(timer.timings.get("resolution", 0.0), 4),
            # the CPU of this process: every simulated robot's; over another transport the
            # robots' own times are in the report's team section
            "cpu_s": round(resolution_cpu, 4) if config.transport == "sim" else None,
            "transport": config.transport,
        },
        "fusion": {"enabled": False, "reason": "labelled landmarks come without camera poses"},
        "triangulation": {"enabled": False, "reason": "no camera poses"},
        "baselines": baselines,
        **({"team": st["team"]} if "team" in st else {}),
        "ground_truth": {"kind": "labelled landmarks: row k of every keypoint file is landmark "
                                 "k; a row 'nan nan' is a landmark the image does not see"},
        "feature_landmarks": [f.landmarks.tolist() for f in frames],
        "versions": versions(),
        "config": {**asdict(config), "out": str(out)},
    }
    why = NO_LANDMARK_LINKS_WHY
    if len(input_links) and not len(links):  # the matches were there: the votes took them all
        why = (f"the --refine votes step removed all {len(input_links)} matches, none won a "
               "strict majority of its two-hop votes; --refine none keeps them")
    flag_result(report, names, no_links_why=why)
    with timer.stage("write", str(out)):
        with atomic_run_folder(out) as tmp:
            ledger = ledger_from_consistency(res)
            ledger.truth = truth.astype(np.int8)
            write_links_csv(tmp / "links.csv", ledger)
            report["timings_s"] = {k: round(v, 4) for k, v in timer.timings.items()}
            write_json_atomic(tmp / "report.json", report)
    return out, report


def landmarks_markdown(report: dict) -> str:
    """The run's table: links, sets, pairwise P/R/F1 before and after, baselines."""
    from pipeline.evaluation.metrics import score_text

    b, a, r, pw = report["before"], report["after"], report["resolution"], report["pairwise"]
    lines = [f"## {report['title']}", "", "| | before | after |", "|---|---:|---:|"]
    for label, key in (("Links", "links"), ("Good links", "good_links"),
                       ("Spurious links", "spurious_links"), ("Missing links", "missing_links"),
                       ("Association sets", "association_sets"),
                       ("Conflictive sets", "conflictive_sets")):
        lines.append(f"| {label} | {b[key]} | {a[key]} |")
    for key, label in (("precision", "precision"), ("recall", "recall"), ("f1", "F1")):
        lines.append(f"| Pairwise {label} (closure) | {score_text(pw['before'], key)} | "
                     f"{score_text(pw['after'], key)} |")
    lines.append(f"| Pairwise F1 of the Hungarian matches themselves | "
                 f"{score_text(pw['input_links'], 'f1')} | |")
    lines.append(f"| Pairwise F1 of the links themselves | {score_text(pw['before_links'], 'f1')} "
                 "| |")
    lines.append(f"| Cycle-consistent | {report['cycle_consistent_before']} | "
                 f"{report['cycle_consistent']} |")
    ref = report["refinement"]
    if ref["method"] == "votes":
        lines += ["", f"Refinement (votes): {ref['iterations']} iteration(s), fixed point "
                      f"{ref['fixed_point']}, {ref['rounds']} rounds, {ref['messages']} messages, "
                      f"{ref['bytes']} bytes, changed {ref['changed_per_iteration']}, "
                      f"{report['timings_s'].get('refine', 0.0):.2f} s"]
    lines += ["", f"Resolution ({r['method']}): {r['deleted_links']} links cut "
                  f"({r['good_deleted']} good / {r['spurious_deleted']} spurious) in "
                  f"{r['iterations']} iteration(s), {r['detection_rounds']} + "
                  f"{r['resolution_rounds']} rounds, {r['messages']} messages, {r['bytes']} bytes, "
                  f"{r['time_s']:.2f} s"]
    if report["baselines"]:
        lines += ["", "| Centralized baseline | precision | recall | F1 | time [s] |",
                  "|---|---:|---:|---:|---:|"]
        for name, bl in report["baselines"].items():
            p = bl["pairwise"]
            lines.append(f"| {name} | {score_text(p, 'precision')} | {score_text(p, 'recall')} | "
                         f"{score_text(p, 'f1')} | {bl['time_s']:.2f} |")
    return "\n".join(lines) + "\n"
