"""Does the links' quality carry evidence? A check from the links' own cycles.

The merge rules (``sync``, ``evidence``) read a link's quality as growing with the confidence
that it is right (``1 - Lowe ratio``, :func:`pipeline.matching.link_evidence.ratio_llr`). A
links file from elsewhere may hold a quality that means nothing (drawn at random, a constant)
or the reverse (a descriptor distance). No truth is needed to see it: the cycles of the links
sort many of them. A link over which a triangle closes (a third camera where both ends match
one common feature) is *confirmed*; a link whose ends are both linked into third cameras, none
of which closes a triangle, is *refuted*. Right links are mostly confirmed, wrong ones mostly
refuted, so a quality that carries evidence is higher on the confirmed links.

The check compares the two groups' qualities by the Mann-Whitney test: the area under the
ROC curve (``auc``, the probability that a confirmed link has the higher quality, ties half;
0.5 when the quality tells nothing) and the one-sided p-values of "higher on the confirmed"
(``p_higher``) and "higher on the refuted" (``p_reversed``; ``resolve`` warns ``quality-reversed`` below
:data:`pipeline.outcome.REVERSED_P`). Measured
(``bench/multiway.py --evidence-check``, the sum of the same test on each labelled input):
0.79–0.99 on the CMU hotel inputs, 0.70–0.92 on warped copies matched by SIFT, 0.49–0.51 on
the synthetic team whose qualities are drawn independently of whether a match is right.

Centralized: it reads every link (a report's figure, as the baselines are), not a robot's.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import InputError
from pipeline.types import Links

__all__ = ["quality_evidence", "MAX_CHECKED"]

MAX_CHECKED = 50_000
"""Links the check classifies at most; beyond it (or beyond :data:`MAX_ENTRIES`), links
drawn in a random order (a fixed seed, over the links sorted by their ends: the rows' order
in the file draws nothing) until either is reached."""
MAX_ENTRIES = 2_000_000
"""Neighbour-list entries the check reads at most (a link costs the degrees of its two ends):
its cost follows these, not the input's triangles (a dense 101-image input, 151,500 links of
about 100 neighbours per feature, took over a minute and 1 GB counted whole)."""


def _check_ids(links: Links, m: np.ndarray) -> None:
    """InputError naming the first link with a camera or feature id out of range: it would be
    read as another camera's feature (a wrong verdict, no error). Either end may come first."""
    ci, fi, cj, fj = links.cam_i, links.feat_i, links.cam_j, links.feat_j
    n = m.shape[0]
    bad = (ci < 0) | (cj < 0) | (ci >= n) | (cj >= n)
    what = f"camera id out of range 0..{n - 1}"
    if not bad.any():
        bad = (fi < 0) | (fj < 0) | (fi >= m[ci]) | (fj >= m[cj])
        what = "feature id out of range"
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        detail = "" if what.startswith("camera") else \
            f" (camera {ci[k]} has {m[ci[k]]} features, camera {cj[k]} has {m[cj[k]]})"
        raise InputError(f"link {k} ({ci[k]},{fi[k]})-({cj[k]},{fj[k]}): {what}{detail}")


def quality_evidence(features_per_camera, links: Links, max_checked: int = MAX_CHECKED,
                     max_entries: int = MAX_ENTRIES) -> dict:
    """The check of the module docstring on ``links`` (on the first links of a random order
    with a fixed seed when they are more than ``max_checked`` or their ends' degrees add up to
    more than ``max_entries``: ``checked`` says how many).

    Returns
    -------
    dict — ``checked``, ``confirmed``, ``refuted`` (link counts), ``constant`` (every link
    has one quality: nothing to test), and where both groups are non-empty and the quality
    varies, ``auc``, ``p_higher``, ``p_reversed``.
    """
    from scipy.stats import mannwhitneyu

    from pipeline.association import camera_offsets
    from pipeline.consistency.keys import isin_sorted, ranges

    for name, v in (("max_checked", max_checked), ("max_entries", max_entries)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise InputError(f"{name} {v!r}: give a whole number of links (entries) >= 0")
    off = camera_offsets(features_per_camera)
    _check_ids(links, np.diff(off))
    q = np.asarray(links.quality, dtype=np.float64)
    L = len(links)
    out = {"checked": 0, "confirmed": 0, "refuted": 0,
           "constant": bool(L == 0 or np.all(q == q[0]))}
    # qualities above 1 cannot be 1 - Lowe ratio: the merge rules clip the ratio at
    # RATIO_EPS, so a score on another scale (0-100, inlier counts) is read as near-certain
    # everywhere and its order barely weighs (warned as quality-scale)
    out["above_one"] = 0 if out["constant"] else int(np.count_nonzero(q > 1.0))
    if L == 0:
        return out
    a = (off[links.cam_i] + links.feat_i).astype(np.int64)
    b = (off[links.cam_j] + links.feat_j).astype(np.int64)
    M = np.int64(off[-1])
    cam = np.repeat(np.arange(len(off) - 1, dtype=np.int64), np.diff(off))
    # every feature's neighbours, sorted (CSR)
    src, dst = np.r_[a, b], np.r_[b, a]
    order = np.lexsort((dst, src))
    src, dst = src[order], dst[order]
    ptr = np.searchsorted(src, np.arange(M + 1))
    deg = np.diff(ptr)
    cost = deg[a] + deg[b]
    if L <= max_checked and int(cost.sum()) <= max_entries:
        pick = np.arange(L)
    else:
        # the draw is over the links, not the rows: the same links in another row order (or
        # with their ends swapped) are checked alike
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        canon = np.lexsort((q, hi, lo))
        perm = canon[np.random.default_rng(0).permutation(L)[:max_checked]]
        take = max(1, int(np.searchsorted(np.cumsum(cost[perm]), max_entries, side="right")))
        pick = np.sort(perm[:take])
    pa, pb = a[pick], b[pick]
    # τ ≥ 1: a neighbour of a (not b) that is a neighbour of b too (its camera is neither's)
    na = ranges(ptr[pa], ptr[pa + 1])
    row = np.repeat(np.arange(pick.size), ptr[pa + 1] - ptr[pa])
    z = dst[na]
    edges = np.unique(src * M + dst)
    common = (z != pb[row]) & isin_sorted(pb[row] * M + z, edges)
    tri = np.zeros(pick.size, dtype=bool)
    tri[row[common]] = True
    # shared ≥ 1: a third camera both ends are linked into
    n = np.int64(len(off) - 1)
    nb = ranges(ptr[pb], ptr[pb + 1])
    row_b = np.repeat(np.arange(pick.size), ptr[pb + 1] - ptr[pb])
    cams_b = np.unique(row_b * n + cam[dst[nb]])
    shared = np.zeros(pick.size, dtype=bool)
    shared[row[isin_sorted(row * n + cam[z], cams_b)]] = True
    qk = q[pick]
    confirmed, refuted = qk[tri], qk[~tri & shared]
    out.update(checked=int(pick.size), confirmed=int(confirmed.size), refuted=int(refuted.size))
    if out["constant"] or not confirmed.size or not refuted.size:
        return out
    higher = mannwhitneyu(confirmed, refuted, alternative="greater")
    lower = mannwhitneyu(confirmed, refuted, alternative="less")
    out.update(auc=float(higher.statistic) / (confirmed.size * refuted.size),
               p_higher=float(higher.pvalue), p_reversed=float(lower.pvalue))
    return out
