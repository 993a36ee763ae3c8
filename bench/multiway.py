"""Benchmark: multi-way matching on labelled data — every rule and every baseline on one input.

For each case (data set × comm graph × input) the same links go to

* the distributed rules of :mod:`pipeline.consistency.rules` (``paper``, ``evidence``,
  ``sync``), run by :func:`pipeline.consistency.resolve_conflicts` in the simulator, and
* the centralized baselines: spectral synchronization (Pachauri et al. 2013) and a
  CLEAR-style normalized spectral method with its universe-size estimate (Fathian et al.
  2020) from :mod:`pipeline.consistency.spectral`, union-find dropping the
  conflictive sets and the constrained greedy merge by link quality
  (:mod:`pipeline.consistency.centralized`).

Each method runs in a child process of its own (fork), so its peak memory is its own
(``peak_rss_mb``: the child's peak resident set, including what it inherited at the fork,
``base_rss_mb``); a child is capped at ``--cap-gb`` of address space and ``--cap-s`` seconds
and reported as refused/out of memory/timed out rather than killing the bench.

Scores are CLEAR's: pairwise precision, recall and F1 of the matches implied by the closure
of the kept links (every two features in one association set), against the labels.
``cycle_consistent``: no association set holds two features of one image.

Cases
    * Labelled landmarks (default ``../shared/data/cmu_hotel``, ``--frames 20 101``), graphs
      ``complete``, ``seq:4``, ``ring2``; inputs ``descriptors`` (Hungarian matches of the
      given descriptors only: the input CLEAR is benchmarked on), ``guided`` (epipolar
      guidance on the labelled positions: what ``run-landmarks`` does by default for ``sync``
      and ``evidence``) and ``guided+votes`` (then two-hop votes: its default for ``paper`` and
      ``paper-labels``, :func:`pipeline.runs.landmarks.default_refinement`). Every image's
      landmarks are presented in a seeded random order (``--shuffle-seed``): the files list
      them in label order, and any tie broken by index would otherwise read the truth.
    * A synthetic team (``--team 300``): ``n`` cameras on a ring2 graph, each seeing the same
      30 landmarks in its own random order; every linked pair matched one-to-one, and 30 % of
      the pairs swap two of their matches (wrong links). Methods: ``resolve:sync`` (the
      ``resolve`` command on the links written as a file, as a user runs it: its wall time and
      peak RSS in ``resolve_wall_s``, ``resolve_peak_rss_mb``), the rules and the cheap
      baselines (``--team-methods`` adds ``spectral_sync`` or ``clear``: minutes from a few hundred
      cameras on, their sparse eigenproblems converge slowly on a ring). ``--team-seeds``
      (default 0) draws other swaps and qualities. The qualities are drawn independently of
      whether a match is right, so they carry no evidence here; each team row prints the sum
      of the ``sync`` rule's link weights over the input links the truth and each method's
      association join (the objective its greedy merge climbs) and how well the quality
      separates the links the triangles confirm from those they refute (``--evidence-check``
      prints both for the labelled and warped cases too).
    * Graffiti (``--graffiti DIR``, default ``../shared/data/graffiti``; ``''`` skips it) on
      the same graphs, matched as ``run-images`` matches it at its defaults, truth from the
      data set's homographies at 2 px; the oracle too.
    * Rendered formations (``--formations abcd``, ``--formation-seeds 5 6 7 8 9``: seeds the
      rules were not developed on), each on its own comm graph, matched as ``run-formation``
      matches it (SIFT, 640x480), truth at 2 px; the oracle too.

``--renumber S ...``: every labelled case (hotel and warped) also runs with its cameras
numbered in a seeded random order (the same images, links and graph; each image keeps its
features): a rule's decisions should not hang on how the cameras are numbered, and a table
prints, per method, how far its F1 moved from the case's own numbering (``renumber`` in the
rows; the recall ratios below use the own numbering only).

Where each link is known good or spurious (every case but none), ``good_cut`` and
``spurious_cut`` count what each method cut. Method ``good_links`` (on request) keeps exactly
the good links: the association of the input's right links, no link invented, the bound of
every rule's recall (:func:`sparse_recall` prints each method's recall on the sparse graphs
over its recall on the complete graph, the target "at least half"). :func:`baseline_check`
prints, per distributed rule and kind of input, on how many inputs its F1 is above, equal to
and below the best centralized baseline's (the target "at least the best centralized
baseline on every input"), and its largest shortfall.

Prints one table per case and saves ``runs/bench-multiway/results.json``.

Usage: ``.venv/bin/python bench/multiway.py [--data DIR] [--frames 20 101] [--graphs ...]
[--inputs descriptors guided guided+votes] [--methods ...] [--team 300 3000] [--quick]``
(``--quick``: 20 frames, complete graph, descriptors only, formation a seed 5, team of 100,
for the options not given).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import signal
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.errors import one_line_interrupts  # noqa: E402

one_line_interrupts(__name__, __file__)  # a Ctrl-C while the libraries below load

import numpy as np  # noqa: E402

from pipeline.commands.options import given_options, positive_argument, seed_argument  # noqa: E402
from pipeline.errors import InputError, one_line_errors  # noqa: E402
from pipeline.outputs import results_folder_problem  # noqa: E402
from pipeline.runfolder import write_json_atomic  # noqa: E402
from pipeline.types import Links  # noqa: E402

#: where every bench looks for the shared data sets by default (CMU hotel, Graffiti, Sceaux):
#: ``../shared/data`` beside the clone, whatever the current folder
SHARED_DATA = ROOT.parent / "shared" / "data"

DISTRIBUTED = ("paper", "paper-labels", "evidence", "sync")
CENTRALIZED = ("spectral_sync", "clear", "drop_conflictive_sets", "quality_merge")


# --------------------------------------------------------------------------- the cases


class Case:
    """One input of the bench: links, features per camera, comm graph and how to score.

    Truth comes as ``truth_id`` (the landmark of every feature: labelled data, the synthetic
    team) or as ``true_pairs`` (every true pair of global feature ids: rendered formations,
    Graffiti's homographies) with ``link_good`` (each link good or spurious). ``evidence``
    holds what the evidence rule reads where the input has it (link weights, keypoints,
    projections); without it every rule reads the links' quality."""

    def __init__(self, m, edges, links, *, truth_id=None, true_pairs=None, link_good=None,
                 evidence=None, weights=None):
        self.m, self.edges, self.links = m, edges, links
        self.weights = weights  # each link's weight as the sync robots compute it, or None
        self.quality_check: dict = {}  # sync_evidence's test of the quality's information
        if link_good is None and truth_id is not None:
            off = np.concatenate([[0], np.cumsum(m)])
            link_good = truth_id[off[links.cam_i] + links.feat_i] == \
                truth_id[off[links.cam_j] + links.feat_j]
        self.truth_id, self.true_pairs, self.link_good = truth_id, true_pairs, link_good
        self.evidence = evidence or {}

    def scores(self, kept: np.ndarray) -> dict:
        out = scores(self.m, self.links.subset(kept), self.truth_id) if self.truth_id is not None \
            else pair_scores(self.m, self.links.subset(kept), self.true_pairs)
        if self.link_good is not None:
            good = self.link_good
            out.update(good_cut=int((~kept & good).sum()), spurious_cut=int((~kept & ~good).sum()))
        if self.truth_id is not None:
            out["links_split"] = links_split(self.m, self.links, kept)
        if self.weights is not None:
            out["evidence_kept"] = evidence_kept(self.m, self.links, kept, self.weights)
        return out


def formation_case(formation: str, seed: int) -> Case:
    """A rendered formation with its own comm graph, matched as ``run-formation`` matches it
    (SIFT, 640x480, merge radius of the default rule), truth at 2 px."""
    import data_synth
    from pipeline.evaluation.links import link_truth
    from pipeline.evaluation.metrics import true_pairs_all
    from pipeline.matching.features import extract_all
    from pipeline.matching.link_evidence import link_evidence
    from pipeline.matching.pairs import match_edges
    from pipeline.stages import merge_radius_for

    fm = data_synth.render(formation, seed=seed, size=(640, 480))
    views, edges = fm.views, np.asarray(fm.comm_edges)
    feats = extract_all(views, "sift", 2000, merge_radius_for("evidence", None))
    matches = match_edges(feats, views, edges)
    links = Links.from_matches(matches)
    m = np.array([len(f) for f in feats], dtype=np.int64)
    ev = link_evidence(matches, links, views, feats)
    return Case(m, edges, links, true_pairs=true_pairs_all(fm, feats, tol_px=2.0),
                link_good=np.asarray(link_truth(fm, feats, links, tol_px=2.0), dtype=bool),
                evidence=dict(link_weight=ev.weight, keypoints=[f.keypoints for f in feats],
                              projections=[v.K @ np.c_[v.R, v.t] for v in views]))


def graffiti_case(directory: str, graph: str) -> Case:
    """Graffiti matched as ``run-images`` matches it at its defaults (features, matcher, merge
    radius; cameras in file-name order, the homographies' order); truth from the data set's
    homographies at 2 px (mutual)."""
    from pipeline.commgraph import comm_graph
    from pipeline.evaluation.truth import (
        _image_scales,
        homography_link_truth,
        homography_true_pairs,
        read_homographies,
    )
    from pipeline.inputs.photos import load_folder
    from pipeline.matching.link_evidence import link_evidence
    from pipeline.progress import StageTimer
    from pipeline.runs.images import ImagesConfig
    from pipeline.stages import extract_and_match, photo_merge_radius

    c = ImagesConfig(directory=directory, graph=graph)
    views = load_folder(directory, max_size=c.max_size, intrinsics="auto")
    edges = comm_graph(graph, [v.name for v in views])
    feats, matches, links = extract_and_match(
        views, edges, c.features, c.max_features, StageTimer(verbose=False),
        contrast_threshold=c.contrast_threshold,
        merge_radius=photo_merge_radius(c.features, c.resolution, None), rootsift=c.rootsift,
        threshold_px=c.threshold_px, budget_after_merge=c.budget_after_merge, matcher=c.matcher)
    kps = [np.asarray(f.keypoints, dtype=np.float64) for f in feats]
    H1 = read_homographies(directory, len(views))
    scales = _image_scales(Path(directory), views)
    m = np.array([len(k) for k in kps], dtype=np.int64)
    ev = link_evidence(matches, links, views, feats)
    return Case(m, edges, links, true_pairs=homography_true_pairs(kps, H1, scales, 2.0),
                link_good=homography_link_truth(kps, links, H1, scales, 2.0),
                evidence=dict(link_weight=ev.weight, keypoints=[f.keypoints for f in feats]))



#: images of a warped copy of ``--data`` (:func:`warped_landmarks`)
WARPED_FRAMES = 30


def check_data_frames(data: str, frames: list[int], warped: bool) -> None:
    """Before any case: ``data`` holds the labelled images the cases take, ``frames`` of them
    (``--frames``) and :data:`WARPED_FRAMES` for the warped copies (``warped``: any
    ``--warped-seeds``); InputError naming the option and what to do. A small folder was
    refused only when the case came, after the cases before it, and a warped copy's refusal
    named ``--frames 30``, a value no one gave."""
    from pipeline.inputs.landmarks import load_landmark_folder

    if not frames and not warped:
        return
    held = len(load_landmark_folder(data))
    if bad := [f for f in frames if not 2 <= f <= held]:
        raise InputError(f"--frames {bad[0]}: expected 2..{held} (--data {data} holds {held} "
                         "labelled images)")
    if warped and held < WARPED_FRAMES:
        raise InputError(f"--warped-seeds: the warped copies take {WARPED_FRAMES} labelled images "
                         f"of --data {data}, which holds {held}; give a larger set, or "
                         "--warped-seeds with no seed to skip them")


def warped_landmarks(directory: str, out: Path, seed: int, frames: int = WARPED_FRAMES,
                     hide: float = 0.0) -> Path:
    """A harder labelled set from ``directory`` (CMU hotel's layout): ``frames`` images at a
    fixed stride, each warped by its own random homography (rotation up to 25°, scale 0.6–1.2,
    a perspective term), blurred (σ up to 1.5 px), with gain and noise, and its labelled
    positions moved alike (plus 1 px of noise); a warp that would move a landmark out of the
    image is drawn again; with ``hide``, each image also loses that fraction of its
    landmarks, drawn at random (written ``nan nan``: landmarks not seen by every image, the
    universe larger than any image). The same landmarks through other "cameras": matched by SIFT at the
    keypoints (``descriptors sift``), for a labelled set whose matches are far noisier than
    the hotel's own. Seeded: the same ``seed`` gives the same set."""
    import cv2

    from pipeline.inputs.landmarks import load_landmark_folder

    fr = load_landmark_folder(directory, "auto", frames)
    n_rows = max(int(f.landmarks.max()) + 1 for f in fr)
    rng = np.random.default_rng(seed)
    out.mkdir(parents=True, exist_ok=True)
    for k, f in enumerate(fr):
        img = cv2.imread(str(f.image_path), cv2.IMREAD_GRAYSCALE)
        h, w = img.shape
        for _ in range(1000):
            ang, s = np.deg2rad(rng.uniform(-25, 25)), rng.uniform(0.6, 1.2)
            A = np.array([[np.cos(ang) * s, -np.sin(ang) * s, 0], [np.sin(ang) * s,
                                                                   np.cos(ang) * s, 0], [0, 0, 1]])
            P = np.eye(3)
            P[2, :2] = rng.uniform(-6e-4, 6e-4, 2)
            H = np.array([[1, 0, w / 2], [0, 1, h / 2], [0, 0, 1]]) @ P @ A @ \
                np.array([[1, 0, -w / 2], [0, 1, -h / 2], [0, 0, 1]])
            pts = cv2.perspectiveTransform(f.keypoints.reshape(-1, 1, 2).astype(np.float64),
                                           H).reshape(-1, 2) + rng.normal(0, 1.0, (len(f.keypoints), 2))
            if pts.min() >= 1 and (pts[:, 0] <= w - 2).all() and (pts[:, 1] <= h - 2).all():
                break
        else:
            raise RuntimeError(f"no warp keeps every landmark of {f.name} inside the image")
        im = cv2.warpPerspective(img, H, (w, h), borderMode=cv2.BORDER_REFLECT)
        sigma = rng.uniform(0, 1.5)
        if sigma > 0.1:
            im = cv2.GaussianBlur(im, (0, 0), sigma)
        im = np.clip(im * rng.uniform(0.6, 1.3) + rng.normal(0, 6, im.shape), 0, 255)
        cv2.imwrite(str(out / f"warped{k:03d}.png"), im.astype(np.uint8))
        rows = np.full((n_rows, 2), np.nan)
        rows[f.landmarks] = pts  # a landmark the source image does not see stays 'nan nan'
        if hide > 0:
            rows[rng.choice(n_rows, int(round(hide * n_rows)), replace=False)] = np.nan
        np.savetxt(out / f"warped{k:03d}.txt", rows, fmt="%.2f")
    return out


def landmark_case(directory: str, frames: int | None, graph: str, inputs: str, seed: int,
                  descriptors: str = "auto"):
    """Links, features per camera and the true landmark of every feature (shuffled order);
    ``auto`` descriptors as ``run-landmarks`` reads them: the ``.scf`` files where the folder
    has them, else SIFT at the keypoints."""
    from pipeline.commgraph import comm_graph
    from pipeline.inputs.landmarks import load_landmark_folder
    from pipeline.matching.landmarks import match_landmark_edges
    from pipeline.matching.votes import refine_by_votes

    fr = load_landmark_folder(directory, descriptors, frames)
    rng = np.random.default_rng(seed)
    perms = [rng.permutation(len(f.keypoints)) for f in fr]
    m = np.array([len(f.keypoints) for f in fr], dtype=np.int64)
    edges = comm_graph(graph, [f.name for f in fr])
    geometry = "none" if inputs == "descriptors" else "epipolar"
    links, _ = match_landmark_edges([f.descriptors[p] for f, p in zip(fr, perms, strict=True)],
                                    edges, fr[0].descriptor_kind, None,
                                    [f.keypoints[p] for f, p in zip(fr, perms, strict=True)],
                                    geometry, 3.0)
    if inputs == "guided+votes":
        links, _ = refine_by_votes(m, edges, links, 10)
    return Case(m, edges, links, truth_id=np.concatenate([f.landmarks[p] for f, p in
                                                          zip(fr, perms, strict=True)]))


def renumbered(case: Case, seed: int) -> Case:
    """``case`` with its cameras numbered in a seeded random order: camera ``i`` becomes
    ``perm[i]``, keeping its features, links, quality and truth (each link written with its
    lower camera first)."""
    perm = np.random.default_rng(seed).permutation(len(case.m))
    m = case.m[np.argsort(perm)]
    a, b = perm[case.links.cam_i], perm[case.links.cam_j]
    swap = a > b
    L = case.links
    links = Links(np.where(swap, b, a), np.where(swap, L.feat_j, L.feat_i), np.where(swap, a, b),
                  np.where(swap, L.feat_i, L.feat_j), L.quality)
    edges = np.sort(perm[np.asarray(case.edges, np.int64).reshape(-1, 2)], axis=1)
    off, off2 = np.concatenate([[0], np.cumsum(case.m)]), np.concatenate([[0], np.cumsum(m)])
    truth = np.empty_like(case.truth_id)
    for i in range(len(case.m)):
        truth[off2[perm[i]]:off2[perm[i]] + case.m[i]] = case.truth_id[off[i]:off[i + 1]]
    return Case(m, edges, links, truth_id=truth)


def renumber_table(records: list) -> list[str]:
    """Per method, the largest change of F1 between a labelled case's own camera numbering
    and its renumberings (``--renumber``)."""
    key_of = lambda r: tuple(r.get(k) for k in ("case", "data", "frames", "graph", "inputs",  # noqa: E731
                                                 "warp_seed", "hidden", "method"))
    own = {key_of(r): r["f1"] for r in records
           if r.get("status") == "ok" and r.get("renumber") is None}
    moved: dict = {}
    for r in records:
        if r.get("status") == "ok" and r.get("renumber") is not None and key_of(r) in own:
            d = abs(r["f1"] - own[key_of(r)])
            best = moved.get(r["method"])
            if best is None or d > best[0]:
                moved[r["method"]] = (d, r)
    lines = []
    for method, (d, r) in moved.items():
        lines.append(f"  {method}: F1 moved by at most {d:.3f} ({r['case']} {r['frames']} "
                     f"frames, {r['graph']}, {r['inputs']}, renumbering seed {r['renumber']}: "
                     f"{own[key_of(r)]:.3f} -> {r['f1']:.3f})")
    return lines


def team_case(n: int, k: int = 30, p_swap: float = 0.3, seed: int = 0):
    """``n`` cameras on a ring2 graph, each seeing the same ``k`` landmarks (own order)."""
    from pipeline.commgraph import graph_edges

    rng = np.random.default_rng(seed)
    perms = [rng.permutation(k) for _ in range(n)]
    inv = [np.argsort(p) for p in perms]  # inv[i][landmark] = feature of camera i
    edges = graph_edges("ring2", n)
    ci, fi, cj, fj, q = [], [], [], [], []
    for i, j in edges.tolist():
        tgt = np.arange(k)
        if rng.random() < p_swap:
            a, b = rng.choice(k, 2, replace=False)
            tgt[a], tgt[b] = tgt[b], tgt[a]
        ci.append(np.full(k, i)), fi.append(inv[i]), cj.append(np.full(k, j))
        fj.append(inv[j][tgt]), q.append(rng.uniform(0.2, 0.6, k))
    links = Links(np.concatenate(ci), np.concatenate(fi), np.concatenate(cj),
                  np.concatenate(fj), np.concatenate(q))
    return Case(np.full(n, k, dtype=np.int64), edges, links, truth_id=np.concatenate(perms))


# --------------------------------------------------------------------------- scoring


def scores(m, kept: Links, truth_id) -> dict:
    """Pairwise P/R/F1 of the closure of ``kept`` against equal labels; cycle consistency.

    Counted per association set without listing pairs: a set of ``s`` features implies
    ``s (s-1) / 2`` pairs, of which ``c (c-1) / 2`` are right for each label it holds ``c``
    times; the true pairs are ``n (n-1) / 2`` per label seen ``n`` times (each image holds
    each label once, so every true pair joins two images)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from pipeline.consistency.centralized import is_conflict_free

    off = np.concatenate([[0], np.cumsum(m)])
    total = int(off[-1])
    a = off[kept.cam_i] + kept.feat_i
    b = off[kept.cam_j] + kept.feat_j
    g = coo_matrix((np.ones(a.size), (a, b)), shape=(total, total))
    _, comp = connected_components(g, directed=False)

    def pairs(counts):
        counts = counts.astype(np.int64)
        return int((counts * (counts - 1) // 2).sum())

    predicted = pairs(np.bincount(comp))
    _, per = np.unique(comp.astype(np.int64) * (int(truth_id.max()) + 1) + truth_id,
                       return_counts=True)
    correct = pairs(per)
    true = pairs(np.unique(truth_id, return_counts=True)[1])
    p = correct / predicted if predicted else 0.0
    r = correct / true if true else 0.0
    return dict(precision=p, recall=r, f1=2 * p * r / (p + r) if p + r else 0.0,
                cycle_consistent=bool(is_conflict_free(m, kept)))


def links_split(m, links: Links, kept: np.ndarray) -> int:
    """Input links whose two ends the association (the closure of the kept links) separates.

    Each input link is one observation; where every feature has a true landmark, the truth
    separates exactly the spurious links, so an association that separates more input links
    than the truth explains the input less well than the truth under any model in which each
    link is wrong independently with one probability below 1/2."""
    from pipeline.association import AssociationGraph, camera_offsets

    comp = AssociationGraph(m, links.subset(kept)).components()
    off = camera_offsets(m)
    a = off[links.cam_i] + links.feat_i
    b = off[links.cam_j] + links.feat_j
    return int((comp[a] != comp[b]).sum())


def evidence_kept(m, links: Links, kept: np.ndarray, w: np.ndarray) -> float:
    """Sum of the weights ``w`` of the input links whose ends the association (the closure of
    the kept links) joins: the objective the greedy merge of ``sync`` climbs (each link's
    ``w`` read as its log-odds of being right, an association keeping the links it joins)."""
    from pipeline.association import AssociationGraph, camera_offsets

    comp = AssociationGraph(m, links.subset(kept)).components()
    off = camera_offsets(m)
    joined = comp[off[links.cam_i] + links.feat_i] == comp[off[links.cam_j] + links.feat_j]
    return float(np.sum(w[joined]))


def sync_evidence(m, links: Links) -> tuple[np.ndarray, dict]:
    """Each input link's weight ``w`` as the ``sync`` robots compute it (their support round
    on the simulator: local evidence plus the cycles' support), in the input's order, and how
    well the quality tells the links the cycles confirm from those they refute
    (:func:`pipeline.evaluation.quality.quality_evidence`: the area under the ROC curve, 0.5
    when it tells nothing, and the one-sided Mann-Whitney p-value; the same for the quality's
    log-odds ``λ``, a strictly increasing function of it)."""
    from pipeline.commgraph import comm_edges_for
    from pipeline.consistency.engines.driver import build_robots
    from pipeline.consistency.engines.sync_batched import run_sync_batched
    from pipeline.consistency.sync import equip_sync
    from pipeline.matching.link_evidence import ratio_llr
    from pipeline.transport.simulated import Network

    robots, index = build_robots(m, links)
    lam = ratio_llr(1.0 - links.quality)
    for rb, li in zip(robots, index, strict=True):
        equip_sync(rb, lam[li])
    run_sync_batched(robots, Network(len(m), comm_edges_for(m, links)))
    w = np.empty(len(links))
    for rb, li in zip(robots, index, strict=True):
        w[li] = rb.sync.w
    from pipeline.evaluation.quality import quality_evidence

    qe = quality_evidence(m, links, max_checked=len(links), max_entries=2**62)  # every link
    check = dict(confirmed=qe["confirmed"], refuted=qe["refuted"])
    if "auc" in qe:
        check.update(auc=qe["auc"], p=qe["p_higher"])
    return w, check


def pair_scores(m, kept: Links, true_pairs) -> dict:
    """Pairwise P/R/F1 of the closure of ``kept`` against listed true pairs; consistency."""
    from pipeline.consistency.centralized import is_conflict_free
    from pipeline.evaluation.metrics import PairwiseTruth

    s = PairwiseTruth(true_pairs, int(np.sum(m))).scores(m, kept)
    return dict(precision=s["precision"], recall=s["recall"], f1=s["f1"],
                cycle_consistent=bool(is_conflict_free(m, kept)))


# --------------------------------------------------------------------------- the methods


def quality_as_written(quality: np.ndarray) -> np.ndarray:
    """The links' quality, ``(L,)``, as ``resolve`` reads it: finite. A Hungarian pair whose
    one end sits at descriptor distance 0 from another landmark has the ratio ``d / 0 = inf``
    (:func:`pipeline.matching.landmarks.match_landmark_edges`), so quality ``1 - inf = -inf``,
    which a links file cannot give. Written at least one below the lowest finite quality (and
    below 0), such a link keeps its place in every order of the qualities (and of their
    :func:`~pipeline.matching.link_evidence.ratio_llr`) that the rules follow in the pipeline:
    below every other link, tied with the other links of ratio inf.

    >>> quality_as_written(np.array([0.5, -np.inf, -2.0])).tolist()
    [0.5, -3.0, -2.0]
    """
    q = np.asarray(quality, dtype=np.float64)
    floor = min(float(q[np.isfinite(q)].min(initial=0.0)), 0.0) - 1.0
    return np.where(q == -np.inf, floor, q)


def run_resolve_cli(rule: str, m, edges, links: Links, cap_gb: float) -> dict:
    """``formation-match resolve --resolution RULE`` on the links written as a CSV file, as a
    user runs it (reading, checks, the stage, writing): kept mask, the child's wall time and
    peak RSS. Its memory guard gets the bench's cap (``--max-memory-gb``): the guard's
    estimate is an upper bound (a 10,000-camera team estimated at 2.3 GB peaks at 1.0 GB),
    and the row reports what the job takes."""
    import csv
    import subprocess

    with tempfile.TemporaryDirectory() as tmp:
        src, graph, out = Path(tmp, "links.csv"), Path(tmp, "graph.csv"), Path(tmp, "out.csv")
        np.savetxt(src, np.stack([links.cam_i, links.feat_i, links.cam_j, links.feat_j,
                                  quality_as_written(links.quality)], axis=1),
                   fmt=["%d"] * 4 + ["%.6f"],
                   delimiter=",", header="cam_i,feat_i,cam_j,feat_j,quality", comments="")
        np.savetxt(graph, edges, fmt="%d", delimiter=",")
        t0 = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-f", "%M", sys.executable, "-m", "pipeline",
                               "resolve", "--links", str(src), "--comm-graph", str(graph),
                               "--out", str(out), "--resolution", rule, "-q",
                               "--max-memory-gb", str(cap_gb)],
                              capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:  # its last line is /usr/bin/time's, then its exit status
            said = [x for x in proc.stderr.strip().splitlines()[:-1]
                    if not x.startswith("Command ")]
            raise RuntimeError(said[-1] if said else f"exit {proc.returncode}")
        with open(out, newline="") as f:
            kept = np.array([r["status"] == "kept" for r in csv.DictReader(f)])
    rss = int(proc.stderr.strip().splitlines()[-1]) / 1024
    return dict(kept=kept, resolve_wall_s=round(wall, 2), resolve_peak_rss_mb=round(rss, 1))


def run_method(method: str, case: Case, cap_gb: float) -> dict:
    """Kept mask and the method's own figures (rounds, messages, bytes where distributed)."""
    m, edges, links = case.m, case.edges, case.links
    if method.startswith("resolve:"):
        return run_resolve_cli(method.split(":", 1)[1], m, edges, links, cap_gb)
    if method == "good_links":
        return dict(kept=np.asarray(case.link_good, dtype=bool).copy())
    if method == "oracle":
        from pipeline.evaluation.oracle import oracle_cut

        return dict(kept=np.asarray(oracle_cut(m, links, case.link_good), dtype=bool))
    if method in DISTRIBUTED:
        from pipeline.consistency import resolve_conflicts

        res = resolve_conflicts(m, edges, links, resolution=method, **case.evidence)
        st = res.stats
        return dict(kept=~res.deleted, rounds=int(st["detection_rounds"] +
                                                   st["resolution_rounds"]),
                    messages=int(st["messages"]), bytes=int(st["bytes"]),
                    max_robot_memory_bytes=int(st["max_robot_memory_bytes"]))
    from pipeline.consistency.centralized import BASELINES

    return dict(kept=np.asarray(BASELINES[method](m, links), dtype=bool))


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def measured(method: str, case, cap_gb: float, cap_s: float) -> dict:
    """Run ``method`` on ``case`` in a forked child; its scores, times and peak memory."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: one method, then its figures through the pipe
        os.close(r)
        out: dict
        try:
            base = _rss_mb()
            resource.setrlimit(resource.RLIMIT_AS, (int(cap_gb * 2**30), int(cap_gb * 2**30)))
            signal.alarm(math.ceil(cap_s))  # int(): under 1 s, no alarm at all
            t0, c0 = time.perf_counter(), time.process_time()
            res = run_method(method, case, cap_gb)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            kept = res.pop("kept")
            out = dict(status="ok", wall_s=round(wall, 3), cpu_s=round(cpu, 3),
                       base_rss_mb=round(base, 1),
                       peak_rss_mb=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                                         / 1024, 1),
                       **case.scores(kept), **res)
        except MemoryError:
            out = dict(status=f"out of memory (cap {cap_gb:g} GB)")
        except Exception as exc:  # noqa: BLE001 - reported in the table
            name = type(exc).__name__
            out = dict(status=f"{name}: {str(exc).splitlines()[0][:120]}",
                       trace=traceback.format_exc()[-2000:])
        with os.fdopen(w, "w") as f:
            json.dump(out, f)
        os._exit(0)
    os.close(w)
    with os.fdopen(r) as f:
        text = f.read()
    _, status = os.waitpid(pid, 0)
    if not text:
        sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
        return dict(status=f"timed out after {cap_s:g} s" if sig == signal.SIGALRM
                    else f"killed (signal {sig})")
    return json.loads(text)


# --------------------------------------------------------------------------- the table


def table(title: str, rows: list[dict]) -> str:
    cut = any("good_cut" in row for row in rows)
    extra = " good cut | spurious cut |" if cut else ""
    lines = [f"## {title}", "",
             "| method | P | R | F1 | consistent |" + extra + " wall [s] | CPU [s] | peak RSS [MB] "
             "| rounds | bytes |",
             "|---|---:|---:|---:|---|" + ("---:|---:|" if cut else "") + "---:|---:|---:|---:|---:|"]
    for row in rows:
        if row.get("status") != "ok":
            lines.append(f"| {row['method']} | {row.get('status')} |" + " |" * (8 + 2 * cut))
            continue
        cuts = f" {row.get('good_cut', '')} | {row.get('spurious_cut', '')} |" if cut else ""
        lines.append(
            f"| {row['method']} | {row['precision']:.3f} | {row['recall']:.3f} | "
            f"{row['f1']:.4f} | {row['cycle_consistent']} |{cuts} {row['wall_s']:.2f} | "
            f"{row['cpu_s']:.2f} | {row['peak_rss_mb']:.0f} | {row.get('rounds', '')} | "
            f"{row.get('bytes', '')} |")
    return "\n".join(lines) + "\n"


def sparse_recall(records: list) -> list[dict]:
    """The target "sparse graphs: recall at least half the complete graph's": for every input
    run on the complete graph and on sparser ones (the same data, frames, input and warp), each
    method's recall on the sparse graph over its recall on the complete one."""
    key_of = lambda r: tuple((k, r.get(k)) for k in ("case", "data", "frames", "inputs",  # noqa: E731
                                                       "warp_seed", "hidden", "method"))
    records = [r for r in records if r.get("renumber") is None]
    complete = {key_of(r): r["recall"] for r in records
                if r.get("status") == "ok" and r.get("graph") == "complete"}
    out = []
    for r in records:
        ref = complete.get(key_of(r))
        if r.get("status") != "ok" or r.get("graph") in (None, "complete") or not ref:
            continue
        out.append({**dict(key_of(r)), "graph": r["graph"], "recall": r["recall"],
                    "recall_complete": ref, "ratio": r["recall"] / ref})
    return out


def baseline_check(records: list) -> list[dict]:
    """The target "on every data set and graph: F1 at least the best centralized baseline on
    the same input": for every input (case, data, frames, graph, input, warp seed and hidden
    fraction, team size and seed, formation and seed) on which a distributed rule and at
    least one centralized baseline ran, the rule's F1 against the best baseline's. Scores are
    compared as the tables print them (4 decimals): ``above``, ``equal`` or ``below``."""
    keys = ("case", "data", "frames", "graph", "inputs", "warp_seed", "hidden", "cameras",
            "team_seed", "formation", "seed")
    groups: dict = {}
    for r in records:
        if r.get("status") == "ok" and r.get("renumber") is None:
            groups.setdefault(tuple(r.get(k) for k in keys), {})[r["method"]] = r["f1"]
    out = []
    for key, f1 in groups.items():
        central = {m: f1[m] for m in CENTRALIZED if m in f1}
        if not central:
            continue
        best = max(central, key=lambda m: (round(central[m], 4), m))
        ref = round(central[best], 4)
        for method in DISTRIBUTED:
            if method in f1:
                got = round(f1[method], 4)
                out.append({**dict(zip(keys, key, strict=True)), "method": method, "f1": f1[method],
                            "best_baseline": best, "baseline_f1": central[best],
                            "verdict": "above" if got > ref else "equal" if got == ref
                            else "below"})
    return out


def baseline_lines(checks: list[dict]) -> list[str]:
    """One line per distributed rule and kind of input (case and input): how many inputs it
    is above, equal to and below the best centralized baseline, and its largest shortfall."""
    lines = []
    kinds = dict.fromkeys((c["method"], c["case"], c["inputs"]) for c in checks)
    for method, case, inputs in kinds:
        mine = [c for c in checks if (c["method"], c["case"], c["inputs"]) == (method, case, inputs)]
        n = {v: sum(c["verdict"] == v for c in mine) for v in ("above", "equal", "below")}
        line = (f"  {method}, {case}" + (f" ({inputs})" if inputs else "") + f": above on "
                f"{n['above']}, equal on {n['equal']}, below on {n['below']} of {len(mine)}")
        if n["below"]:
            w = min(mine, key=lambda c: c["f1"] - c["baseline_f1"])
            where = ", ".join(f"{k} {w[k]}" for k in ("frames", "graph", "warp_seed", "hidden",
                                                       "cameras", "team_seed", "formation",
                                                       "seed") if w.get(k) is not None)
            line += (f"; largest shortfall {w['f1'] - w['baseline_f1']:+.4f} ({where}: "
                     f"{w['f1']:.4f} against {w['best_baseline']}'s {w['baseline_f1']:.4f})")
        lines.append(line)
    return lines


def run_case(title: str, case: Case, methods, base: dict, a, records: list) -> None:
    """Every method on one case: rows appended to ``records``, the table printed."""
    rows = []
    for method in methods:
        if method in ("oracle", "good_links") and case.link_good is None:
            continue
        row = dict(**base, method=method, **measured(method, case, a.cap_gb, a.cap_s))
        rows.append(row)
        records.append(row)
    before = case.scores(np.ones(len(case.links), dtype=bool))
    print(table(f"{title} (input closure F1 {before['f1']:.3f}, {len(case.links)} links)", rows),
          flush=True)
    if case.truth_id is not None:
        split = ", ".join(f"{r['method']} {r['links_split']}" for r in rows if "links_split" in r)
        print(f"input links separated: the truth {int((~case.link_good).sum())} (the spurious "
              f"ones); {split}", flush=True)
    if case.weights is not None:
        truth = float(np.sum(case.weights[case.link_good]))
        ev = ", ".join(f"{r['method']} {r['evidence_kept']:.2f}" for r in rows
                       if "evidence_kept" in r)
        print(f"evidence of the input links each association joins (sum of the sync rule's "
              f"weights): the truth {truth:.2f}; {ev}", flush=True)
    qc = case.quality_check
    if "auc" in qc:
        print(f"quality as evidence: AUC {qc['auc']:.3f} (one-sided p {qc['p']:.1e}) of the "
              f"quality's log-odds between the {qc['confirmed']} links a triangle confirms "
              f"and the {qc['refuted']} the shared third cameras refute", flush=True)
    print(flush=True)


def machine(load_at_start: float) -> dict:
    """What a results file says of the machine: cores, Python, the load average at the start
    of the bench and now (its end)."""
    return {"cpus": os.cpu_count(), "python": platform.python_version(),
            "load_average_at_start": round(load_at_start, 2),
            "load_average_at_end": round(os.getloadavg()[0], 2)}


#: what ``--quick`` runs, for each option not given
QUICK = {"frames": [20], "graphs": ["complete"], "inputs": ["descriptors"], "team": [100],
         "warped_seeds": [1], "warped_hide": [0.25], "warped_inputs": ["descriptors"],
         "graffiti": "", "formations": "a", "formation_seeds": [5]}


@one_line_errors
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default=str(SHARED_DATA / "cmu_hotel"))
    p.add_argument("--frames", type=int, nargs="*", default=[20, 50, 101],
                   help="labelled cases with these frame counts (none: only the team rows)")
    p.add_argument("--graphs", nargs="+", default=["complete", "seq:4", "ring2"])
    p.add_argument("--inputs", nargs="+", default=["descriptors", "guided", "guided+votes"],
                   choices=("descriptors", "guided", "guided+votes"))
    p.add_argument("--methods", nargs="+", default=[*DISTRIBUTED, *CENTRALIZED])
    p.add_argument("--graffiti", default=str(SHARED_DATA / "graffiti"),
                   help="the Graffiti folder (H1to{k}p); '' skips it")
    p.add_argument("--formations", default="abcd", help="formations to render ('' none)")
    p.add_argument("--formation-seeds", type=seed_argument, nargs="*", default=[5, 6, 7, 8, 9])
    p.add_argument("--warped-seeds", type=seed_argument, nargs="*", default=[1, 2, 3],
                   help="warped copies of --data (warped_landmarks), 30 frames each, SIFT at "
                        "the keypoints; none: skip")
    p.add_argument("--warped-inputs", nargs="+", default=["descriptors", "guided"],
                   help="inputs of the warped cases (as --inputs; guided = run-landmarks' "
                        "default matching)")
    p.add_argument("--warped-hide", type=float, nargs="*", default=[0.0, 0.25],
                   help="fractions of each warped image's landmarks hidden (nan rows)")
    p.add_argument("--team", type=int, nargs="*", default=[300])
    p.add_argument("--evidence-check", action="store_true",
                   help="on the labelled and warped cases too (always on the team rows): the "
                        "sum of the sync rule's weights over the input links each association "
                        "joins, and how well the quality tells the links the triangles "
                        "confirm from those they refute")
    p.add_argument("--team-seeds", type=seed_argument, nargs="+", default=[0],
                   help="seeds of the team rows (which pairs swap, the qualities drawn)")
    p.add_argument("--team-methods", nargs="+",
                   default=["resolve:sync", "sync", "evidence", "drop_conflictive_sets",
                            "quality_merge"],
                   help="methods of the team rows; resolve:RULE runs the resolve command")
    p.add_argument("--shuffle-seed", type=seed_argument, default=0)
    p.add_argument("--renumber", type=seed_argument, nargs="*", default=[],
                   help="also run every labelled case with its cameras renumbered by these "
                        "seeds (decisions should not depend on the numbering)")
    p.add_argument("--cap-gb", type=positive_argument, default=6.0)
    p.add_argument("--cap-s", type=positive_argument, default=600.0)
    p.add_argument("--quick", action="store_true",
                   help="small values for the options not given: " + ", ".join(
                       f"--{k.replace('_', '-')} "
                       + (" ".join(map(str, v)) if isinstance(v, list) else v or "''")
                       for k, v in QUICK.items()))
    p.add_argument("--out", default=str(ROOT / "runs" / "bench-multiway"))
    a = p.parse_args(argv)
    if problem := results_folder_problem(a.out):
        p.error(problem)
    from pipeline.consistency.centralized import BASELINES
    from pipeline.consistency.rules import RULES

    known = [*DISTRIBUTED, *BASELINES, "oracle", "good_links", *(f"resolve:{r}" for r in RULES)]
    for flag, methods in (("--methods", a.methods), ("--team-methods", a.team_methods)):
        if unknown := [x for x in methods if x not in known]:
            p.error(f"{flag} {' '.join(unknown)}: unknown; choose from {', '.join(known)}")
    if a.team and min(a.team) < 2:
        p.error(f"--team {min(a.team)}: a team has at least 2 cameras")
    if a.quick:  # small values for the options not given (--quick --frames 6 runs 6 frames)
        given = given_options(p, argv)
        for dest, value in QUICK.items():
            if dest not in given:
                setattr(a, dest, value)
    import data_synth

    for formation in a.formations:  # before the labelled, warped and Graffiti cases run
        data_synth.check_formation(formation)
    check_data_frames(a.data, a.frames, bool(a.warped_seeds and a.warped_hide))
    records = []
    load = os.getloadavg()[0]
    for frames in a.frames:
        for graph in a.graphs:
            for inputs in a.inputs:
                case = landmark_case(a.data, frames, graph, inputs, a.shuffle_seed)
                if a.evidence_check:
                    case.weights, case.quality_check = sync_evidence(case.m, case.links)
                title = f"{Path(a.data).name}, {frames} frames, {graph}, {inputs}"
                base = dict(case="landmarks", data=Path(a.data).name, frames=frames,
                            graph=graph, inputs=inputs)
                run_case(title, case, a.methods, base, a, records)
                for seed in a.renumber:
                    run_case(f"{title}, cameras renumbered (seed {seed})", renumbered(case, seed),
                             a.methods, dict(base, renumber=seed), a, records)
    from pipeline.matching.link_evidence import RATIO_EPS

    for hide in a.warped_hide:
        for wseed in a.warped_seeds:
            with tempfile.TemporaryDirectory() as tmp:
                wdir = warped_landmarks(a.data, Path(tmp) / f"warped-{wseed}", wseed, hide=hide)
                for graph in a.graphs:
                    for inputs in a.warped_inputs:
                        case = landmark_case(str(wdir), None, graph, inputs, a.shuffle_seed,
                                             descriptors="sift")
                        if a.evidence_check:
                            case.weights, case.quality_check = sync_evidence(case.m, case.links)
                        beyond = 1.0 - case.links.quality >= 1.0 - RATIO_EPS  # the clip
                        print(f"links with ratio >= 0.99 (an assignment beyond the nearest "
                              f"neighbour): {beyond.mean():.2f}, right among them "
                              f"{case.link_good[beyond].mean():.2f}")
                        hidden = f", {hide:g} hidden" if hide else ""
                        title = (f"{Path(a.data).name} warped (seed {wseed}{hidden}), 30 frames, "
                                 f"{graph}, SIFT at the keypoints, {inputs}")
                        base = dict(case="warped", data=Path(a.data).name, warp_seed=wseed,
                                    hidden=hide, frames=30, graph=graph, inputs=f"sift {inputs}")
                        run_case(title, case, a.methods, base, a, records)
                        for seed in a.renumber:
                            run_case(f"{title}, cameras renumbered (seed {seed})",
                                     renumbered(case, seed), a.methods,
                                     dict(base, renumber=seed), a, records)
    if a.graffiti:
        for graph in a.graphs:
            case = graffiti_case(a.graffiti, graph)
            run_case(f"{Path(a.graffiti).name}, {graph}, run-images defaults", case,
                     [*a.methods, "oracle"], dict(case="graffiti", data=Path(a.graffiti).name,
                                                  graph=graph, inputs="defaults"), a, records)
    for formation in a.formations:
        for seed in a.formation_seeds:
            case = formation_case(formation, seed)
            run_case(f"formation {formation}, seed {seed}, its comm graph, run-formation matching",
                     case, [*a.methods, "oracle"],
                     dict(case="formation", formation=formation, seed=seed, graph="formation",
                          inputs="defaults"), a, records)
    for n in a.team:
        for seed in a.team_seeds:
            case = team_case(n, seed=seed)
            case.weights, case.quality_check = sync_evidence(case.m, case.links)
            run_case(f"team of {n} cameras, ring2, 30 landmarks, 30 % of pairs with a swap, "
                     f"seed {seed}", case, a.team_methods,
                     dict(case="team", cameras=n, graph="ring2", team_seed=seed), a, records)
    if a.renumber:
        print("F1 under camera renumbering (--renumber " + " ".join(map(str, a.renumber)) + ")")
        print("\n".join(renumber_table(records)))
    ratios = sparse_recall(records)
    if ratios:
        print("recall on a sparse graph over the complete graph's (target: at least 0.5)")
        for method in dict.fromkeys(x["method"] for x in ratios):
            got = [x["ratio"] for x in ratios if x["method"] == method]
            worst = min(ratios, key=lambda x: x["ratio"] if x["method"] == method else 9)
            print(f"  {method}: {min(got):.3f}–{max(got):.3f} over {len(got)} inputs, "
                  f"{sum(g >= 0.5 for g in got)} at 0.5 or more; lowest: {worst['case']} "
                  f"{worst['frames']} frames, {worst['graph']}, {worst['inputs']}"
                  + (f", warp seed {worst['warp_seed']}, hidden {worst['hidden']:g}"
                     if worst["warp_seed"] is not None else ""))
    checks = baseline_check(records)
    if checks:
        print("F1 against the best centralized baseline on the same input (target: at least it "
              "on every input)")
        print("\n".join(baseline_lines(checks)))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "results.json", {
        "machine": machine(load), "args": vars(a), "records": records, "sparse_recall": ratios,
        "baseline_check": checks, "renumbering": renumber_table(records)})
    print(f"saved {out / 'results.json'} (load average {load:.1f} at start, "
          f"{os.getloadavg()[0]:.1f} at end)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
