"""Exact ground truth for photographs of a planar scene with known homographies.

Data sets such as the Oxford "graffiti" sequence give, for every image ``k``, the homography
``H_1k`` from image 1 to image ``k`` (files ``H1to{k}p.txt``, 3 x 3, pixel coordinates of the
full-resolution images). Every pair then has its true mapping ``H_ij = H_1j · H_1i⁻¹``, so
the synthetic-only figures of a run (good / spurious / missing links, pairwise P/R/F1, the
baselines' scores) exist for these photographs too.

Definitions (tolerance ``tol_px`` in pixels of the images as processed, default 2 px as for
the rendered formations, docs/DESIGN.md "Conventions"):

* *good link* ``(i, r)–(j, s)``: ``H_ij`` maps keypoint ``r`` within ``tol_px`` of keypoint
  ``s`` **and** ``H_ji`` maps ``s`` within ``tol_px`` of ``r`` (mutually); *spurious*
  otherwise.
* *true pairs* of an image pair: keypoints ``r`` of ``i`` and ``s`` of ``j`` that are each
  other's nearest neighbour after the mapping in both directions, within ``tol_px`` both
  ways — one-to-one, between detected keypoints.
* *missing link*: a true pair on a communication edge that matching did not return.

Keypoints are in the OpenCV pixel convention (origin at the centre of the top-left pixel);
images downscaled by ``(s_x, s_y)`` map to full resolution by ``x_full = (x + ½)/s_x − ½``.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["TRUTH_KINDS", "read_homographies", "pair_homography", "apply_homography",
           "homography_link_truth", "homography_true_pairs", "fill_report", "truth_doubt"]

TRUTH_KINDS = ("none", "homographies")
DEFAULT_TOL_PX = 2.0


def read_homographies(directory: str | Path, n: int) -> np.ndarray:
    """``H_1k`` for ``k = 1..n`` (images in name order), ``(n, 3, 3)``; ``H_11 = I``.

    Reads ``DIR/H1to{k}p.txt`` (or ``H1to{k}.txt``) for ``k = 2..n``.

    Raises
    ------
    InputError
        A missing file, or one that is not a 3 x 3 numeric matrix with a finite inverse.
    """
    directory = Path(directory)
    H = np.zeros((n, 3, 3))
    H[0] = np.eye(3)
    for k in range(2, n + 1):
        cands = [directory / f"H1to{k}p.txt", directory / f"H1to{k}.txt"]
        path = next((c for c in cands if c.is_file()), None)
        if path is None:
            raise InputError(f"{directory}: no homography file H1to{k}p.txt for image {k} of "
                             f"{n} (name order); --truth homographies needs one per image 2..n")
        try:
            with warnings.catch_warnings():  # an empty file: the shape check below names it
                warnings.simplefilter("ignore", UserWarning)
                h = np.loadtxt(path, dtype=np.float64)
        except ValueError as exc:
            raise InputError(f"{path}: not a numeric 3 x 3 matrix ({exc})") from None
        if h.shape != (3, 3):
            raise InputError(f"{path}: expected an invertible 3 x 3 homography, got shape "
                             f"{h.shape}")
        if not np.isfinite(h).all():
            raise InputError(f"{path}: the homography holds a non-finite value (nan or inf); "
                             "expected an invertible 3 x 3 matrix of numbers")
        # a homography is defined up to scale (a DLT solution has unit norm, H1to{k}p.txt files
        # end in 1): tested and kept at the scale of its largest entry, where a determinant
        # tells a singular matrix from a small one
        top = float(np.abs(h).max())
        hn = h / top if top > 0 else h
        if abs(np.linalg.det(hn)) < 1e-12:
            raise InputError(f"{path}: the homography is singular (determinant "
                             f"{np.linalg.det(h):.3g}); expected an invertible 3 x 3 matrix")
        H[k - 1] = hn
    return H


def truth_doubt(good: np.ndarray, tol_px: float, names: list[str] | None = None) -> str | None:
    """A warning when the homographies likely do not describe these images, else None: at
    least 20 links and under 5 % of them within ``tol_px`` (matching finds right links on a
    planar scene far more often than that; homographies of the originals given with resized
    copies find almost none: measured 0 of 515 on Graffiti downscaled to 640 px). ``names``:
    the images' names, to say which one is image 1 of the files (the first in name order; a
    folder without the reference image pairs every file with the wrong image)."""
    n = int(np.size(good))
    if n < 20 or float(np.mean(good)) >= 0.05:
        return None
    order = ""
    if names:
        first = sorted(names)
        order = (f"; image k of H1to{{k}}p is the k-th image in name order: image 1 is "
                 f"{first[0]}, image 2 {first[1]}" if len(first) > 1 else "")
    return (f"only {int(np.sum(good))} of {n} links agree with the homographies within "
            f"{tol_px:g} px: are the H1to{{k}}p.txt files for these images at this size "
            f"(resized copies need their homographies rescaled){order}?")


def pair_homography(H1: np.ndarray, i: int, j: int) -> np.ndarray:
    """``H_ij = H_1j · H_1i⁻¹`` (image ``i`` → image ``j``, full-resolution pixels)."""
    return H1[j] @ np.linalg.inv(H1[i])


def apply_homography(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``(N, 2)`` points mapped by ``H``; points mapped to infinity become ``nan``."""
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    x = pts @ H[:, :2].T + H[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = x[:, :2] / x[:, 2:3]
    out[~np.isfinite(out).all(axis=1)] = np.nan
    return out


def _to_full(pts: np.ndarray, scale: np.ndarray) -> np.ndarray:
    return (np.asarray(pts, dtype=np.float64) + 0.5) / scale - 0.5


def _to_processed(pts: np.ndarray, scale: np.ndarray) -> np.ndarray:
    return (pts + 0.5) * scale - 0.5


def _map(H1, scales, i: int, j: int, pts: np.ndarray) -> np.ndarray:
    """Keypoints of processed image ``i`` mapped into processed image ``j``."""
    full = apply_homography(pair_homography(H1, i, j), _to_full(pts, scales[i]))
    return _to_processed(full, scales[j])


def homography_link_truth(keypoints: list[np.ndarray], links: Links, H1: np.ndarray,
                          scales: np.ndarray, tol_px: float = DEFAULT_TOL_PX) -> np.ndarray:
    """Good (True) / spurious (False) of every link, ``(L,)`` (module notes: mutually).

    Parameters
    ----------
    keypoints : list of (m_i, 2) — processed-image pixels
    links : Links, (L,)
    H1 : (n, 3, 3) — ``H_1k`` of :func:`read_homographies`
    scales : (n, 2) — ``(s_x, s_y)`` processed / full size of every image
    tol_px : float
    """
    good = np.zeros(len(links), dtype=bool)
    if not len(links):
        return good
    key = links.cam_i * (len(keypoints) + 1) + links.cam_j
    for k in np.unique(key):
        idx = np.flatnonzero(key == k)
        i, j = int(links.cam_i[idx[0]]), int(links.cam_j[idx[0]])
        xi = keypoints[i][links.feat_i[idx]]
        xj = keypoints[j][links.feat_j[idx]]
        e_ij = np.linalg.norm(_map(H1, scales, i, j, xi) - xj, axis=1)
        e_ji = np.linalg.norm(_map(H1, scales, j, i, xj) - xi, axis=1)
        good[idx] = (e_ij <= tol_px) & (e_ji <= tol_px)  # nan compares False
    return good


def _true_pairs_of(kp_i, kp_j, H1, scales, i, j, tol_px) -> np.ndarray:
    """``(Q, 2)`` local ids ``(r, s)``: mutual nearest neighbours after the mapping."""
    if not len(kp_i) or not len(kp_j):
        return np.zeros((0, 2), dtype=np.int64)
    pi = _map(H1, scales, i, j, kp_i)
    pj = _map(H1, scales, j, i, kp_j)
    ok_i = np.isfinite(pi).all(axis=1)
    ok_j = np.isfinite(pj).all(axis=1)
    d_ij, s = cKDTree(kp_j).query(np.where(ok_i[:, None], pi, 1e12))
    d_ji, r = cKDTree(kp_i).query(np.where(ok_j[:, None], pj, 1e12))
    rr = np.arange(len(kp_i))
    mutual = ok_i & (d_ij <= tol_px)
    mutual[mutual] &= (r[s[mutual]] == rr[mutual]) & (d_ji[s[mutual]] <= tol_px)
    return np.stack([rr[mutual], s[mutual]], axis=1).astype(np.int64)


def homography_true_pairs(keypoints: list[np.ndarray], H1: np.ndarray, scales: np.ndarray,
                          tol_px: float = DEFAULT_TOL_PX) -> np.ndarray:
    """True pairs of every image pair, ``(Q, 2)`` global ids (offsets in camera order)."""
    m = np.array([len(k) for k in keypoints], dtype=np.int64)
    off = np.concatenate([[0], np.cumsum(m)])
    parts = []
    for i in range(len(keypoints)):
        for j in range(i + 1, len(keypoints)):
            p = _true_pairs_of(keypoints[i], keypoints[j], H1, scales, i, j, tol_px)
            parts.append(np.stack([p[:, 0] + off[i], p[:, 1] + off[j]], axis=1))
    return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.int64)


def _missing(true_pairs: np.ndarray, links: Links, comm_edges: np.ndarray, m: np.ndarray) -> int:
    """True pairs on communication edges that ``links`` does not contain. Edges, pairs and
    links are compared as unordered pairs: an edge given as ``(j, i)`` or a link stored from
    its higher camera counts as its ``(i, j)`` (compared as ordered, such an edge's true pairs
    were never counted missing, a figure better than the truth)."""
    off = np.concatenate([[0], np.cumsum(m)])
    cam = np.repeat(np.arange(m.size), m)
    n = m.size
    edges = np.sort(np.asarray(comm_edges, np.int64).reshape(-1, 2), axis=1)
    tp = np.sort(np.asarray(true_pairs, np.int64).reshape(-1, 2), axis=1)
    on_edge = np.isin(cam[tp[:, 0]] * n + cam[tp[:, 1]], edges[:, 0] * n + edges[:, 1])
    tp = tp[on_edge]
    a = off[links.cam_i] + links.feat_i
    b = off[links.cam_j] + links.feat_j
    a, b = np.minimum(a, b), np.maximum(a, b)
    total = int(off[-1]) + 1
    found = np.isin(tp[:, 0] * total + tp[:, 1], a * total + b)
    return int((~found).sum())


def _image_scales(directory: Path, views) -> np.ndarray:
    """``(n, 2)`` processed / full-resolution size of every view (full size from the file)."""
    from PIL import Image

    out = np.ones((len(views), 2))
    for k, v in enumerate(views):
        with Image.open(directory / v.name) as im:
            w, h = im.size
        out[k] = (v.size[0] / w, v.size[1] / h)
    return out


def fill_report(report: dict, directory: str | Path, views, features, comm_edges, ledger,
                tol_px: float = DEFAULT_TOL_PX) -> None:
    """Every ground-truth figure of a run on homography-related photographs, in place.

    Sets ``ledger.truth`` (1 good, 0 spurious) and fills ``report``: ``before`` / ``after``
    (good, spurious, missing links, precision), ``resolution`` (good / spurious cut,
    conflictive sets well / wrongly solved) and ``fusion`` (good / spurious cut), ``baselines`` (recomputed with the truth: good / spurious / missing links,
    pairwise), ``pairwise`` (``before``, ``after_resolution``, ``after``) and
    ``ground_truth`` (kind, tolerance, true pairs).

    Parameters
    ----------
    report : dict — a run report with ``before``, ``after``, ``resolution``, ``fusion``
    directory : the image folder (holds ``H1to{k}p.txt``)
    views : list[View] — as processed (possibly downscaled)
    features : list[Features]
    comm_edges : (E, 2) int
    ledger : LinkLedger — every link and what the stages decided
    tol_px : float

    Raises
    ------
    InputError
        Missing or bad homography files (:func:`read_homographies`).
    """
    from pipeline.evaluation import report as sections
    from pipeline.evaluation.metrics import PairwiseTruth

    directory = Path(directory)
    H1 = read_homographies(directory, len(views))
    # image k of the files is the k-th name; the cameras may be in another order (content
    # order, pipeline.inputs.photos.in_content_order)
    rank = {name: k for k, name in enumerate(sorted(v.name for v in views))}
    H1 = H1[[rank[v.name] for v in views]]
    scales = _image_scales(directory, views)
    kps = [np.asarray(f.keypoints, dtype=np.float64) for f in features]
    m = np.array([len(k) for k in kps], dtype=np.int64)
    edges = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
    links = ledger.links
    good = homography_link_truth(kps, links, H1, scales, tol_px)
    ledger.truth = good.astype(np.int8)
    tp = homography_true_pairs(kps, H1, scales, tol_px)
    scorer = PairwiseTruth(tp, int(m.sum()))

    def missing(kept_links: Links) -> int:
        return _missing(tp, kept_links, edges, m)

    def pairwise(kept_links: Links) -> dict:
        return scorer.scores(m, kept_links)

    kept = ledger.kept
    resolved = kept | (ledger.reason == "fusion-outlier")
    for key, mask in (("before", np.ones(len(links), dtype=bool)), ("after", kept)):
        report[key].update(sections.association_counts(m, links.subset(mask), good[mask],
                                                       missing(links.subset(mask))))
    cut = ledger.reason == "resolution"
    well, wrong = sections.sets_solved(ledger, good)
    report["resolution"].update(good_deleted=int((cut & good).sum()),
                                spurious_deleted=int((cut & ~good).sum()),
                                sets_well_solved=well, sets_wrongly_solved=wrong)
    fused = ledger.reason == "fusion-outlier"
    report["fusion"].update(cut_good=int((fused & good).sum()),
                            cut_spurious=int((fused & ~good).sum()))
    report["baselines"] = sections.baselines_section(m, links, good, missing, pairwise)
    report["pairwise"] = {"before": pairwise(links), "after_resolution": pairwise(
        links.subset(resolved)), "after": pairwise(links.subset(kept))}
    report["ground_truth"] = {"kind": "homographies H_ij = H_1j H_1i^-1, mutual reprojection",
                              "tolerance_px": tol_px, "true_pairs": int(len(tp)),
                              "doubt": truth_doubt(good, tol_px, [v.name for v in views])}
