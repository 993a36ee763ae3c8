"""Evidence-aware decentralized resolution of conflictive sets (alternative to Alg. 1).

The detection of Sec. III (Aragüés et al.) leaves every robot of a conflictive set ``C`` with
the list of its features (the row ``X_i·(t_i)`` of any conflictive feature). The paper's
Alg. 1 then cuts where breadth-first waves from the root meet, ignoring which links are
likely wrong. Here the robots of ``C`` instead agree on the cut by *flooding and solving*:

1. **Flood** (rounds ``1 … diam(C)``). Every robot sends, for each of its features in ``C``,
   a *bundle*: the feature's id, its keypoint, its alive links in ``C`` with each link's local
   evidence weight (:mod:`pipeline.matching.link_evidence`, held by both ends of the link since
   matching), and, where its pose is known, its projection matrix ``P = K [R | t]``. Bundles
   go to the neighbours it shares a link of ``C`` with; a robot forwards each bundle it
   receives for the first time to those neighbours. A bundle travels one robot-hop per round,
   and two robots of ``C`` are never more hops apart than two of its features, so every robot
   of ``C`` holds every bundle after ``diam(C) ≤ d`` rounds (``d`` the diameter of the
   association graph, Cor. 3.6).
2. **Solve** (no messages). A robot knows it holds the whole set when it has a bundle for every
   feature of the row ``X_i·(t_i)``; it then runs :func:`evidence_cut` — a deterministic
   function of the set's bundles only — and deletes its own side of every link the solution
   cuts. All robots of ``C`` solve the same problem on the same data, so both ends of every
   link decide alike: deletions are symmetric without reject messages.

:func:`evidence_cut` is a Kruskal merge (the QuickMatch idea of a consistent merge) in order
of decreasing evidence: a link's weight is its local log-likelihood ratio plus
:data:`TRIANGLE_WEIGHT` per *third camera* in which both its ends match one common feature
(triangle support, computed from the set's links; with known poses a third camera counts
only if the triangle's three observations are one point, see :func:`triangle_support`),
counted at face value up to :data:`.cycles.SUPPORT_VIEWS` third cameras both ends are linked
into and beyond as the agreement rate over that many (:func:`.cycles.support_term`, the
``sync`` rule's weight: a confusion repeated across the views of a dense set). Two
clusters merge only if they share no camera (Def. 2.4) and, when every camera of the set has
a known pose, if the point triangulated (linear DLT) from all their observations lies in
front of every camera and reprojects within :data:`REPROJECTION_TOL_PX` of each (the inlier
test of robust fusion, on the merged track). A link is kept iff its two ends end in one
cluster. Hence:

* conflict-free at the end (no cluster holds two features of one camera; every kept link lies
  inside a cluster), after one pass — the next detection finds nothing;
* nothing cut outside conflictive sets (only robots of a set take part, only set links cut);
* a stated round bound: ``diam(C) ≤ d`` rounds to flood, plus one round in which the last
  forwarded copies (redundant) are delivered;
* the one rule: a robot reads its own state and its inbox only; :func:`evidence_cut` sees
  only the bundles the robot received.

Where the member lists come from: the rule's stage (:mod:`.engines.evidence_stage`, and
:func:`.alone.run_evidence_locally` for a robot alone) runs the bounded label flooding of
:mod:`.setlists` instead of the rows of Sec. III: a set of at most ``B`` features (the bundle
budget) reaches this flood and solve with its whole member list, as the rows gave it; a larger
set is merged by the ``sync`` rule on its links instead, so no robot holds more than ``B``
bundles of one set.

Stated choices: ties in weight are broken by the smaller link ``(min gid, max gid)``; the
weight of a link is the one its bundles carry (both ends hold the same value); a robot whose
pose is unknown sends no ``P`` and the geometric test is then skipped for the whole set.

Payload of a ``bundle`` message (counted at ``nbytes``): ``set`` (F,) int64 set labels,
``feat`` (F,) int64 feature ids, ``kp`` (F, 2) float32, ``deg`` (F,) int32, ``nbr`` (D,) int64
the other ends, ``w`` (D,) float64, ``cam`` (F,) int32 and ``P`` (F_P, 3, 4) float64, the
projections of the ``F_P`` bundles that carry one (omitted when none does); when some but not
all do, ``has_P`` (F,) bool says which. A bundle thus arrives exactly as its robot made it,
whatever other bundles share its message, and every robot of a set solves the same problem.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from pipeline.consistency.cycles import shared_cameras, support_term
from pipeline.consistency.keys import isin_sorted, ranges, tie_key
from pipeline.consistency.robot import Robot
from pipeline.errors import StageStalledError
from pipeline.transport import Message, Transport

__all__ = ["EvidenceState", "equip", "evidence_cut", "triangle_support", "common_features",
           "node_cameras", "distinct_cameras", "one_point", "far_point", "start_evidence",
           "evidence_step", "run_evidence_resolution", "TRIANGLE_WEIGHT", "REPROJECTION_TOL_PX",
           "CASE_EVIDENCE", "start_evidence_reliable", "evidence_round",
           "evidence_done", "lookups",
           "own_sets", "own_set_links", "bundle_nbytes", "set_links", "set_problem", "set_geometry",
           "solve_set", "solve_sets", "set_weights", "cut_own_side", "send_bundle_items", "read_bundle_items", "finish_evidence", "evidence_pass", "reexamine_sets"]

Send = Callable[[int, str, dict], None]

#: deletion-log code of a link cut by the evidence rule (next to Alg. 1's b, c in robot.py)
CASE_EVIDENCE = 5
#: log-likelihood ratio added per third camera supporting a link (a triangle of links): a good
#: link's point is matched in a third camera about half the time, two ends of a spurious link
#: meet one common feature in a third camera rarely (≲ 1 in 20): log(0.5 / 0.05) ≈ 2.3. The
#: second premise holds only for triangles whose three observations are one point (with known
#: poses :func:`triangle_support` counts only those): inside a conflictive set a third of the
#: spurious links close a triangle with one good and one spurious link
TRIANGLE_WEIGHT = float(np.log(10.0))
#: largest reprojection error (pixels) of a merged track's observations; the tolerance at which
#: two observations count as one point
REPROJECTION_TOL_PX = 2.0


@dataclass
class EvidenceState:
    """What a robot holds for the evidence rule.

    Attributes
    ----------
    link_weight : ndarray, (L_i,) float64 — local evidence of each row of the link table
    keypoints : ndarray, (m_i, 2) float32
    projection : ndarray (3, 4) float64 or None — ``K [R | t]`` when the pose is known
    bundles : dict ``set label -> {feature gid -> (kp (2,), nbr (k,), w (k,), cam, P)}``
    solved : set of set labels already solved
    set_members : dict ``set label -> (F,) int64`` the features of the set (from ``X``)
    set_nbrs : dict ``set label -> sorted list of robots`` sharing a link of the set
    """

    link_weight: np.ndarray
    keypoints: np.ndarray
    projection: np.ndarray | None
    bundles: dict = field(default_factory=dict)
    solved: set = field(default_factory=set)
    set_members: dict = field(default_factory=dict)
    set_nbrs: dict = field(default_factory=dict)
    held_bytes: int = 0  # bytes of the bundles and set members held, kept as they arrive
    #: the bundle budget ``B`` of :mod:`.setlists` (``None``: the team's default)
    bundle_budget: int | None = None
    #: the stage solves the conflictive sets of at most ``B`` features (its phase 2);
    #: ``False``: it leaves them to its caller (the online stage gathers them at a root)
    solve_small: bool = True
    #: the small sets solved at their roots (:mod:`.roots`): the conflictive ones (the rule's
    #: flood then leaves them, :meth:`floods_small`) and the conflict-free ones
    gather_conflictive: bool = False
    gather_free: bool = False

    def floods_small(self) -> bool:
        """The stage's phase 2 (the rule's flood) solves the small conflictive sets: neither
        left to the caller nor solved at their roots."""
        return self.solve_small and not self.gather_conflictive

    def keep(self, lab: int, g: int, bundle: tuple) -> None:
        """Hold ``bundle = (kp, nbr, w, cam, P)`` of feature ``g`` of set ``lab``."""
        self.bundles[lab][g] = bundle
        self.held_bytes += bundle_nbytes(bundle)

    def nbytes(self) -> int:
        return int(self.link_weight.nbytes + self.keypoints.nbytes + self.held_bytes)


def bundle_nbytes(bundle: tuple) -> int:
    """Bytes a robot holds for one bundle ``(kp, nbr, w, cam, P)``: its arrays, the feature
    id (8) and the camera (4)."""
    kp, nbr, w, _, P = bundle
    return int(kp.nbytes + nbr.nbytes + w.nbytes + 12 + (P.nbytes if P is not None else 0))


def equip(robot: Robot, link_weight, keypoints, projection) -> None:
    """Give a robot its own evidence: weights of its link table rows, keypoints, projection."""
    robot.evidence = EvidenceState(np.asarray(link_weight, dtype=np.float64),
                                   np.asarray(keypoints, dtype=np.float32).reshape(-1, 2),
                                   None if projection is None else
                                   np.asarray(projection, dtype=np.float64).reshape(3, 4))


# --------------------------------------------------------------------------- the set's solution


def triangle_support(a: np.ndarray, b: np.ndarray, cam_of, keypoints: dict | None = None,
                     projections: dict | None = None,
                     tol_px: float = REPROJECTION_TOL_PX) -> np.ndarray:
    """Number of third cameras in which both ends of each link match one common feature.

    Parameters
    ----------
    a, b : ndarray, (E,) int — link ends (feature ids), each link once
    cam_of : callable ``(k,) ids -> (k,) cameras``
    keypoints, projections : dict ``feature id -> (2,)`` and ``-> (3, 4)`` or None
        With both, a common feature ``z`` supports the link ``(x, y)`` only if the triangle's
        three observations are one point: the merge's geometric test (:func:`_consistent`,
        ``tol_px``) on ``[x, y, z]``. ``None``: every common feature counts.
    tol_px : float — reprojection tolerance of that test

    Returns
    -------
    ndarray, (E,) int64

    Notes
    -----
    Why the three-view test. Triangle support stands for *"a third camera saw the same
    point"*, which :data:`TRIANGLE_WEIGHT` prices at 1 in 20 for a spurious link. In a
    conflictive set the premise fails without geometry: the set is where a spurious link
    meets good ones, so its two ends are often both linked to one third feature, through one
    good and one spurious link (repeated texture along a row, seen by a row of cameras: every
    candidate lies on the epipolar line). Measured on the rendered formations a–d, seeds
    0–9, links of conflictive sets: 34 % of the 858 spurious links had support, and their
    weight (``+2.3`` per camera) set them ahead of good links in the merge; the cluster they
    formed then failed the geometric test against the good links of the point, which were
    cut (14 of the 16 good links cut beyond the oracle's on seeds 5–9 fell so). Two
    observations cannot refute a link that lies on its epipolar line, three can: among the
    1754 triangles of three good links there, the three-view DLT reprojects within 1.01 px
    (99 % within 0.52 px); of the 185 triangles holding a spurious link 1 % pass 2 px
    (median 69 px). With the test, 0.1 % of the spurious links keep support and 70 % of the
    good links (71 % before).

    Computed on arrays (:func:`common_features` lists every triangle, :func:`one_point`
    solves their three-view points as one stack of SVDs, each the same ``(6, 4)`` system
    :func:`_consistent` solves for ``[x, y, z]``), so a set's root solving hundreds of
    thousands of triangles is not held up by a Python loop over them.
    """
    a = np.asarray(a, dtype=np.int64).reshape(-1)
    b = np.asarray(b, dtype=np.int64).reshape(-1)
    if a.size == 0:
        return np.zeros(0, dtype=np.int64)
    e, z = common_features(a, b)
    if keypoints is not None and projections is not None and e.size:
        nodes = np.unique(np.r_[a, b])
        kp = np.array([keypoints[g] for g in nodes.tolist()], dtype=np.float64).reshape(-1, 2)
        P = np.array([projections[g] for g in nodes.tolist()],
                     dtype=np.float64).reshape(-1, 3, 4)
        ids = np.searchsorted(nodes, np.stack([a[e], b[e], z], axis=1))
        ok = one_point(kp[ids], P[ids], tol_px)
        e, z = e[ok], z[ok]
    return distinct_cameras(e, np.asarray(cam_of(z), dtype=np.int64), a.size)


def common_features(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle over the links ``(a, b)`` (each once): ``(e, z)``, the link and a feature
    linked to both its ends, one row per such pair, grouped by link."""
    E = a.size
    nodes, inv = np.unique(np.r_[a, b], return_inverse=True)
    N = nodes.size
    ia, ib = inv[:E], inv[E:]
    adj = np.unique(np.r_[ia, ib] * N + np.r_[ib, ia])  # each link in both directions
    ptr = np.searchsorted(adj // N, np.arange(N + 1))
    pos = ranges(ptr[ia], ptr[ia + 1])
    e = np.repeat(np.arange(E), ptr[ia + 1] - ptr[ia])
    z = adj[pos] % N                                   # the neighbours of each link's first end
    common = isin_sorted(z * N + ib[e], adj)           # ... that are neighbours of its second
    return e[common], nodes[z[common]]


def node_cameras(a: np.ndarray, b: np.ndarray, cam_a: np.ndarray, cam_b: np.ndarray):
    """``cam_of``: ``(k,) ids -> (k,) cameras`` for the features that end the links ``(a, b)``
    (their cameras ``cam_a``, ``cam_b``), on arrays."""
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    nodes = np.unique(np.r_[a, b])
    cam = np.empty(nodes.size, dtype=np.int64)
    cam[np.searchsorted(nodes, a)] = cam_a
    cam[np.searchsorted(nodes, b)] = cam_b
    return lambda ids: cam[np.searchsorted(nodes, np.asarray(ids, np.int64))]


def distinct_cameras(e: np.ndarray, cam: np.ndarray, E: int) -> np.ndarray:
    """``(E,)`` int64: per link, the distinct cameras among its rows ``e`` (cameras ``cam``)."""
    if e.size == 0:
        return np.zeros(E, dtype=np.int64)
    C = int(cam.max()) + 1
    pairs = np.unique(e * C + cam)
    return np.bincount(pairs // C, minlength=E).astype(np.int64)


def far_point(kp: np.ndarray, P: np.ndarray, tol: float) -> np.ndarray:
    """Whether rays meet at a distant point: ``kp (T, k, 2)``, ``P (T, k, 3, 4)`` -> ``(T,)``
    bool: the point at infinity in the mean direction of the ``k`` rays (each in front of its
    camera) lies in front of every camera and within ``tol`` px of each observation.

    The DLT's least-squares point is a poor judge where the cameras' centres are (nearly)
    one: one centre (a robot standing still, ``run-formation --steps --speed 0``) lies in the
    DLT system's null space, so its point is the centre itself and the test decided by the
    sign of rounding noise; centres a millimetre apart (a robot creeping, ``--speed 1e-3``)
    leave the depth to the keypoints' noise, and the DLT point landed anywhere on the rays,
    behind a camera or where it reprojects far off, refusing observations of one point (the
    evidence rule then cut a third of the good links of such a run). Rays with (nearly) no
    baseline carry no depth: the observations are one point exactly when their rays agree,
    which the point at infinity tests. It is the same test for any cameras: a point at
    infinity that reprojects within ``tol`` px of every observation explains them as well as
    a finite one does (with a wide baseline the DLT finds such a point itself, far away), so
    it is tried wherever the DLT point is refused."""
    M = P[..., :3]
    h = np.concatenate([kp, np.ones(kp.shape[:-1] + (1,))], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        Minv = np.linalg.pinv(M)
        ray = np.einsum("tkij,tkj->tki", Minv, h)  # M @ ray = h: depth 1, in front
        ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
        p = np.einsum("tkij,tj->tki", M, ray.mean(axis=1))
        err = np.hypot(p[..., 0] / p[..., 2] - kp[..., 0], p[..., 1] / p[..., 2] - kp[..., 1])
    return (p[..., 2] > 0).all(axis=1) & (err <= tol).all(axis=1)


def one_point(kp: np.ndarray, P: np.ndarray, tol: float) -> np.ndarray:
    """:func:`_consistent` on a stack of observation triples: ``kp (T, 3, 2)``,
    ``P (T, 3, 3, 4)`` -> ``(T,)`` bool, the DLT point in front of the three cameras and
    within ``tol`` px of each observation, or else the
    :func:`far_point`."""
    A = np.empty((len(kp), 6, 4))
    A[:, 0::2] = kp[:, :, :1] * P[:, :, 2] - P[:, :, 0]
    A[:, 1::2] = kp[:, :, 1:] * P[:, :, 2] - P[:, :, 1]
    X = np.linalg.svd(A, full_matrices=False)[2][:, -1]
    fin = np.abs(X[:, 3]) >= 1e-12
    X = X / np.where(fin, X[:, 3], 1.0)[:, None]
    p = np.einsum("tkij,tj->tki", P, X)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.hypot(p[..., 0] / p[..., 2] - kp[..., 0], p[..., 1] / p[..., 2] - kp[..., 1])
    ok = fin & (p[..., 2] > 0).all(axis=1) & (err <= tol).all(axis=1)
    if not ok.all():
        ok[~ok] = far_point(kp[~ok], P[~ok], tol)
    return ok


def _consistent(rows: list[int], kp: np.ndarray, P: np.ndarray, tol: float) -> bool:
    """DLT point of the observations ``rows`` of ``kp (N, 2)``, ``P (N, 3, 4)`` in front of
    all and within ``tol`` px, or else the :func:`far_point` of their rays. On arrays: the
    same system row by row (each ``x P[2] - P[0]``, ``y P[2] - P[1]``), the same SVD and
    the same reprojections as one observation at a time, in a fraction of the time (it runs
    once per attempted merge)."""
    x, Pm = kp[rows], P[rows]
    A = np.empty((2 * len(rows), 4))
    A[0::2] = x[:, :1] * Pm[:, 2] - Pm[:, 0]
    A[1::2] = x[:, 1:] * Pm[:, 2] - Pm[:, 1]
    X = np.linalg.svd(A, full_matrices=False)[2][-1]  # V only: U of a long track is (2k, 2k)
    if abs(X[3]) >= 1e-12:
        X = X / X[3]
        p = Pm @ X
        if (p[:, 2] > 0).all() and (np.hypot(p[:, 0] / p[:, 2] - x[:, 0],
                                             p[:, 1] / p[:, 2] - x[:, 1]) <= tol).all():
            return True
    return bool(far_point(x[None], Pm[None], tol)[0])


def evidence_cut(a, b, cam_a, cam_b, weight, keypoints: dict | None = None,
                 projections: dict | None = None,
                 tol_px: float = REPROJECTION_TOL_PX) -> np.ndarray:
    """Cut mask ``(E,)`` of one conflictive set: Kruskal merge by decreasing evidence.

    Parameters
    ----------
    a, b : array_like, (E,) int — link ends (feature ids), each link once
    cam_a, cam_b : array_like, (E,) int — their cameras
    weight : array_like, (E,) float — evidence (log-likelihood ratio, triangle support included)
    keypoints, projections : dict ``feature id -> (2,)`` and ``-> (3, 4)`` or None
        Observations and projection matrices; ``None`` skips the geometric test.
    tol_px : float — reprojection tolerance of a merged track

    Returns
    -------
    cut : ndarray, (E,) bool — after it, no two features of one camera are connected

    Notes
    -----
    ``O(E log E)`` plus one ``(2k × 4)`` SVD per attempted merge of ``k`` observations.
    Deterministic: order by ``(-weight, t, lo, hi)`` (``t`` = :func:`.keys.tie_key`: ties of
    weight in a fixed pseudo-random order, as the ``sync`` merge orders them).
    """
    a = np.asarray(a, dtype=np.int64)
    b = np.asarray(b, dtype=np.int64)
    weight = np.asarray(weight, dtype=np.float64)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((hi, lo, tie_key(lo, hi), -weight))
    parent: dict[int, int] = {}
    cams: dict[int, int] = {}
    members: dict[int, list[int]] = {}

    def find(x: int) -> int:
        root = x
        while parent.get(root, root) != root:
            root = parent[root]
        while parent.get(x, x) != root:
            parent[x], x = root, parent[x]
        return root

    geometric = keypoints is not None and projections is not None
    row: dict[int, int] = {}   # a feature's row in kp, P (the geometric test's arrays)
    if geometric:
        nodes = np.unique(np.r_[a, b]).tolist()
        row = {g: i for i, g in enumerate(nodes)}
        kp = np.array([keypoints[g] for g in nodes], dtype=np.float64).reshape(-1, 2)
        P = np.array([projections[g] for g in nodes], dtype=np.float64).reshape(-1, 3, 4)
    cut = np.zeros(a.size, dtype=bool)
    ca, cb = np.asarray(cam_a).tolist(), np.asarray(cam_b).tolist()
    al, bl = a.tolist(), b.tolist()
    for k in order.tolist():
        ra, rb = find(al[k]), find(bl[k])
        if ra == rb:
            continue
        sa, sb = cams.get(ra, 1 << ca[k]), cams.get(rb, 1 << cb[k])
        if sa & sb:  # Def. 2.4: the merged cluster would hold two features of one camera
            cut[k] = True
            continue
        ma, mb = members.get(ra, [row.get(ra, ra)]), members.get(rb, [row.get(rb, rb)])
        if geometric and not _consistent(ma + mb, kp, P, tol_px):
            cut[k] = True
            continue
        parent[rb] = ra
        cams[ra] = sa | sb
        members[ra] = ma + mb
        members.pop(rb, None)
    # a link cut earlier whose ends were joined later by other links lies inside a cluster
    roots_a = np.array([find(x) for x in al], dtype=np.int64)
    roots_b = np.array([find(x) for x in bl], dtype=np.int64)
    return cut & (roots_a != roots_b)


# --------------------------------------------------------------------------- the robots' rule


def own_set_links(robot: Robot) -> tuple[np.ndarray, ...]:
    """This robot's alive links from its conflictive features, from its own state only.

    Returns ``(label, r, nbr, other, w)``, each ``(D,)``: the set label, own feature, the
    neighbour, the other end's global id and the link's evidence weight, grouped by (set,
    own feature) in ascending order, a feature's links in the order of the link table.
    """
    st: EvidenceState = robot.evidence
    idx = np.flatnonzero(robot.link_alive & robot.conflictive[robot.link_r])
    r = robot.link_r[idx]
    order = np.lexsort((r, robot.set_label[r]))  # stable: table order within a feature
    idx, r = idx[order], r[order]
    nbr = robot.link_nbr[idx]
    other = robot.offsets[nbr] + robot.link_s[idx]  # int64: the offsets are
    return robot.set_label[r], r, nbr, other, st.link_weight[idx]


def own_sets(robot: Robot, links: tuple | None = None) -> dict[int, tuple[np.ndarray, list[int],
                                                                         dict]]:
    """The conflictive sets this robot takes part in, from its own state only.

    ``links``: :func:`own_set_links` of the robot, if already computed.

    Returns
    -------
    dict ``set label -> (members, set_nbrs, bundles)``: ``members`` (F,) int64 the features
    of the set (its row of ``X``, Sec. III), ``set_nbrs`` the sorted robots it shares an
    alive link of the set with, ``bundles`` ``{feature gid -> (kp (2,), nbr (k,), w (k,),
    cam, P)}`` of its own features of the set, in ascending gid: what it floods (a bundle's
    links in the order of the link table). Labels ascend.
    """
    st: EvidenceState = robot.evidence
    labels, r, nbr, other, w = own_set_links(robot) if links is None else links
    if r.size == 0:
        return {}
    # a feature lies in one set: its runs start where r changes; a set's where the label does
    fs = [0, *(np.flatnonzero(r[1:] != r[:-1]) + 1).tolist()]
    fe = [*fs[1:], r.size]
    set_start = [0, *(np.flatnonzero(labels[1:] != labels[:-1]) + 1).tolist()]
    set_stop = [*set_start[1:], r.size]
    X = robot.X
    ptr, ind = X.indptr, X.indices
    out = {}
    feats = r[fs].tolist()
    k = 0
    for a, b in zip(set_start, set_stop, strict=True):
        f0 = feats[k]
        members = ind[ptr[f0]:ptr[f0 + 1]].astype(np.int64)  # its row of X (Sec. III)
        nbrs = sorted(set(nbr[a:b].tolist()))
        bundles = {}
        while k < len(fs) and fs[k] < b:
            f, u, v = feats[k], fs[k], fe[k]
            bundles[robot.gid0 + f] = (st.keypoints[f].copy(), other[u:v], w[u:v], robot.id,
                                       st.projection)
            k += 1
        out[int(labels[a])] = (members, nbrs, bundles)
    return out


def start_evidence(robot: Robot, send: Send) -> int:
    """Round 0: bundle every own conflictive feature and send it to the set neighbours.

    Returns the number of conflictive sets this robot takes part in.
    """
    st: EvidenceState = robot.evidence
    st.bundles, st.solved, st.set_members, st.set_nbrs = {}, set(), {}, {}
    st.held_bytes = 0
    sets = own_sets(robot)
    out: dict[int, list] = {}
    for lab, (members, nbrs, bundles) in sets.items():
        st.set_members[lab] = members
        st.held_bytes += members.nbytes
        st.set_nbrs[lab] = nbrs
        st.bundles[lab] = {}
        for g, bundle in bundles.items():
            st.keep(lab, g, bundle)
        for j in nbrs:
            out.setdefault(j, []).extend((lab, g) for g in bundles)
    _send_bundles(robot, out, send)
    robot.measure_memory()
    robot.peak_memory_bytes = max(robot.peak_memory_bytes, robot.memory_bytes() + st.nbytes())
    return len(sets)


def _send_bundles(robot: Robot, out: dict, send: Send) -> None:
    st: EvidenceState = robot.evidence
    for j in sorted(out):
        items = out[j]
        if not items:
            continue
        send(j, "bundle", send_bundle_items([(x, g, st.bundles[x][g]) for x, g in items]))


def send_bundle_items(items: list) -> dict:
    """The payload of a ``bundle`` message (module docstring) holding ``items``, a list of
    ``(set label, feature gid, bundle)``."""
    bund = [bb for _, _, bb in items]
    payload = {"set": np.array([x for x, _, _ in items], dtype=np.int64),
               "feat": np.array([g for _, g, _ in items], dtype=np.int64),
               "kp": np.stack([bb[0] for bb in bund]).astype(np.float32),
               "deg": np.array([bb[1].size for bb in bund], dtype=np.int32),
               "nbr": np.concatenate([bb[1] for bb in bund]).astype(np.int64),
               "w": np.concatenate([bb[2] for bb in bund]).astype(np.float64),
               "cam": np.array([bb[3] for bb in bund], dtype=np.int32)}
    has_P = np.array([bb[4] is not None for bb in bund], dtype=bool)
    if has_P.any():
        payload["P"] = np.stack([bb[4] for bb in bund if bb[4] is not None]).astype(np.float64)
        if not has_P.all():
            payload["has_P"] = has_P
    return payload


def read_bundle_items(p: dict) -> list:
    """The ``(set label, feature gid, bundle)`` items of a ``bundle`` payload, each bundle
    ``(kp, nbr, w, cam, P)`` exactly as its robot made it."""
    ends = np.r_[0, np.cumsum(p["deg"])]
    proj = _projections(p)
    return [(lab, g, (p["kp"][k], p["nbr"][ends[k]:ends[k + 1]], p["w"][ends[k]:ends[k + 1]],
                      int(p["cam"][k]), proj[k]))
            for k, (lab, g) in enumerate(zip(p["set"].tolist(), p["feat"].tolist(),
                                             strict=True))]


def _projections(p: dict) -> list:
    """The projection each bundle of a ``bundle`` payload carries (``None`` where none)."""
    F = p["feat"].size
    if "P" not in p:
        return [None] * F
    if "has_P" not in p:
        return list(p["P"])
    out: list = [None] * F
    for k, P in zip(np.flatnonzero(p["has_P"]).tolist(), p["P"], strict=True):
        out[k] = P
    return out


def evidence_step(robot: Robot, inbox: list[Message], send: Send, round_: int) -> None:
    """One round: keep the new bundles, forward them, solve every set now complete."""
    st: EvidenceState = robot.evidence
    out: dict[int, list] = {}
    for msg in inbox:
        if msg.kind != "bundle":
            continue
        for lab, g, bundle in read_bundle_items(msg.payload):
            have = st.bundles.get(lab)
            if have is None or g in have:
                continue
            st.keep(lab, g, bundle)
            for j in st.set_nbrs[lab]:
                if j != msg.src:
                    out.setdefault(j, []).append((lab, g))
    _send_bundles(robot, out, send)
    for lab, have in st.bundles.items():
        if lab in st.solved or len(have) < st.set_members[lab].size:
            continue
        st.solved.add(lab)
        _solve_and_cut(robot, lab, round_)
    robot.measure_memory()
    robot.peak_memory_bytes = max(robot.peak_memory_bytes, robot.memory_bytes() + st.nbytes())


def set_links(bundles: dict) -> tuple:
    """The set's links from its bundles, each once, ordered by ``(min, max)`` of their ends:
    ``(a, b, cam_a, cam_b, local)``, ``local`` the weight of each link's first bundle entry
    (its local evidence)."""
    cam = {g: bb[3] for g, bb in bundles.items()}
    a = np.concatenate([np.full(bb[1].size, g, dtype=np.int64) for g, bb in bundles.items()])
    b = np.concatenate([bb[1] for bb in bundles.values()])
    w = np.concatenate([bb[2] for bb in bundles.values()])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    span = int(hi.max(initial=0)) + 1
    key, first = np.unique(lo * span + hi, return_index=True)
    a, b, w = key // span, key % span, w[first]
    cam_a = np.array([cam[g] for g in a.tolist()], dtype=np.int64)
    cam_b = np.array([cam[g] for g in b.tolist()], dtype=np.int64)
    return a, b, cam_a, cam_b, w


def set_problem(bundles: dict) -> tuple:
    """The set's links (each once) with their weights and the geometric data, from bundles.

    Returns ``(a, b, cam_a, cam_b, weight, keypoints, projections)``; ``keypoints`` and
    ``projections`` are ``None`` unless every bundle carries a projection.
    """
    a, b, cam_a, cam_b, w = set_links(bundles)
    kp, P = set_geometry(bundles)
    return a, b, cam_a, cam_b, set_weights(a, b, cam_a, cam_b, w, *lookups(kp, P)), kp, P


def lookups(keypoints: dict | None, projections: dict | None) -> tuple:
    """``(keypoints, projections)`` dicts ``{gid -> ...}`` as the lookups
    :func:`set_weights` takes (``ids -> (k, 2)``, ``ids -> (k, 3, 4)``), or ``(None, None)``."""
    if keypoints is None or projections is None:
        return None, None
    ids = np.array(sorted(keypoints), np.int64)
    kp = np.array([keypoints[g] for g in ids.tolist()], np.float64).reshape(-1, 2)
    P = np.array([projections[g] for g in ids.tolist()], np.float64).reshape(-1, 3, 4)
    return (lambda q: kp[np.searchsorted(ids, q)]), (lambda q: P[np.searchsorted(ids, q)])


def set_geometry(bundles: dict) -> tuple[dict | None, dict | None]:
    """Keypoints ``{gid -> (2,) float64}`` and projections ``{gid -> (3, 4)}`` of a set's
    bundles, or ``(None, None)`` unless every bundle carries a projection."""
    if all(bb[4] is not None for bb in bundles.values()):
        return ({g: bb[0].astype(np.float64) for g, bb in bundles.items()},
                {g: bb[4] for g, bb in bundles.items()})
    return None, None


def solve_set(bundles: dict) -> tuple:
    """The set's solution from its bundles: ``(a, b, cam_a, cam_b, cut)``, each ``(E,)``.

    :func:`set_problem` then :func:`evidence_cut`: a deterministic function of the bundles
    only, so every robot that holds all of a set's bundles computes the same cut.
    """
    a, b, cam_a, cam_b, w, kp, P = set_problem(bundles)
    return a, b, cam_a, cam_b, evidence_cut(a, b, cam_a, cam_b, w, kp, P)


def set_weights(a, b, cam_a, cam_b, local, keypoints=None, projections=None,
                geometric=None, tol_px: float | None = None) -> np.ndarray:
    """The evidence rule's link weights of the links of one set or of several sets at once:
    every caller's (:func:`set_problem`, the robots' roots, the simulator's batched
    solutions) is this one.

    Parameters
    ----------
    a, b : (E,) int — link ends (feature ids), each link once; no link joins two sets
    cam_a, cam_b : (E,) int — their cameras
    local : (E,) float — each link's local evidence (what its bundles carry)
    keypoints, projections : callables ``(k,) ids -> (k, 2)`` and ``-> (k, 3, 4)`` or None
    geometric : (E,) bool or None — the link's set has every projection (the rule's test
        on it); None: all do when ``projections`` is given
    tol_px : float or None — the test's tolerance (default the rule's
        :data:`REPROJECTION_TOL_PX`)

    Returns
    -------
    (E,) float64 — ``local + TRIANGLE_WEIGHT * support_term(tau, shared)``: ``tau`` the third
    cameras in which both ends match one common feature whose three observations are one
    point (:func:`triangle_support`; all common features
    where ``geometric`` is False), ``shared`` the third cameras both ends are linked into
    (:func:`~pipeline.consistency.cycles.shared_cameras`). The sets' triangles are listed at
    once and their three-view points solved as one stack of SVDs: each link's weight is what
    :func:`triangle_support` on its own set gives (``tests/pipeline/consistency/engines/
    test_gather.py`` checks it against that, set by set).
    """
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    cam_a, cam_b = np.asarray(cam_a, np.int64), np.asarray(cam_b, np.int64)
    local = np.asarray(local, np.float64)
    E = a.size
    if E == 0:
        return np.zeros(0)
    tol = REPROJECTION_TOL_PX if tol_px is None else float(tol_px)
    lo, hi = np.minimum(a, b), np.maximum(a, b)   # the rule's order of a link's ends
    e, z = common_features(lo, hi)
    ok = np.ones(e.size, bool)
    geo = np.ones(E, bool) if geometric is None else np.asarray(geometric, bool)
    if keypoints is not None and projections is not None and e.size:
        test = np.flatnonzero(geo[e])
        if test.size:
            ids = np.stack([lo[e[test]], hi[e[test]], z[test]], axis=1)
            ok[test] = one_point(np.asarray(keypoints(ids.ravel()), np.float64).reshape(-1, 3, 2),
                                 np.asarray(projections(ids.ravel()), np.float64)
                                 .reshape(-1, 3, 3, 4), tol)
    e, z = e[ok], z[ok]
    tau = distinct_cameras(e, node_cameras(a, b, cam_a, cam_b)(z), E)
    shared = shared_cameras(a, b, cam_a, cam_b)
    return local + TRIANGLE_WEIGHT * support_term(tau, shared, False)


def solve_sets(bundle_sets: list[dict]) -> list[tuple]:
    """:func:`solve_set` on each of several sets (disjoint: no link joins two of them), with
    the weights of all computed at once (:func:`set_weights`: their triangles' three-view
    points as one stack of SVDs where :func:`set_problem` solves one stack per set). Same
    solutions as :func:`solve_set` on each (``tests/pipeline/consistency/test_solve_sets.py``);
    a root that completes many sets in one round solves them together."""
    parts = []
    for bundles in bundle_sets:
        a, b, cam_a, cam_b, w = set_links(bundles)
        parts.append((a, b, cam_a, cam_b, np.asarray(w, np.float64), *set_geometry(bundles)))
    if not parts:
        return []
    a, b, cam_a, cam_b, local = (np.concatenate([p[k] for p in parts]) for k in range(5))
    geometric = np.concatenate([np.full(p[0].size, p[5] is not None) for p in parts])
    posed = [p for p in parts if p[5] is not None]   # sets with the geometric test
    kp = {g: v for p in posed for g, v in p[5].items()}
    P = {g: v for p in posed for g, v in p[6].items()}
    w = set_weights(a, b, cam_a, cam_b, local, *lookups(kp, P), geometric=geometric)
    out, at = [], 0
    for sa, sb, sca, scb, _, skp, sP in parts:
        e = slice(at, at + sa.size)
        at += sa.size
        out.append((sa, sb, sca, scb, evidence_cut(sa, sb, sca, scb, w[e], skp, sP)))
    return out


def cut_own_side(robot: Robot, solution: tuple, round_) -> None:
    """Delete this robot's side of every link the set's ``solution`` (:func:`solve_set`) cuts.

    ``round_`` : int, the round it solved in, or (E,) int, one per link of ``solution`` (the
    solutions of several sets concatenated, each with its own round).
    """
    a, b, cam_a, cam_b, cut = solution
    _name_pieces(robot, a, b, cut)
    mine = (cam_a == robot.id) | (cam_b == robot.id)
    sel = cut & mine
    if not sel.any():
        return
    rounds = np.broadcast_to(np.asarray(round_), sel.shape)[sel]
    here = cam_a[sel] == robot.id
    own = np.where(here, a[sel], b[sel]) - robot.gid0
    other = np.where(here, b[sel], a[sel])
    other_cam = np.where(here, cam_b[sel], cam_a[sel])
    link = robot.find_links(other_cam, other - robot.offsets[other_cam])
    ok = link >= 0
    ok[ok] = robot.link_r[link[ok]] == own[ok]
    link, rounds = link[ok], rounds[ok]
    fresh = robot.link_alive[link]
    link, rounds = link[fresh], rounds[fresh]
    robot.link_alive[link] = False
    robot.deleted_round[link] = rounds
    robot.deleted_case[link] = CASE_EVIDENCE
    robot.deleted_iteration[link] = robot.iteration


def _name_pieces(robot: Robot, a: np.ndarray, b: np.ndarray, cut: np.ndarray) -> None:
    """Name the track of each own feature of the solved sets: the smallest id of its piece
    (the component of the kept links, the name the next detection of Sec. III would give)."""
    nodes, inv = np.unique(np.r_[a, b], return_inverse=True)
    own = (nodes >= robot.gid0) & (nodes < robot.gid0 + robot.m)
    if not own.any():
        return
    E = a.size
    keep = ~np.asarray(cut, dtype=bool)
    g = sp.csr_matrix((np.ones(int(keep.sum()), dtype=bool), (inv[:E][keep], inv[E:][keep])),
                      shape=(nodes.size, nodes.size))
    _, comp = connected_components(g, directed=False)
    smallest = np.full(int(comp.max(initial=-1)) + 1, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(smallest, comp, nodes)
    robot.track_label[nodes[own] - robot.gid0] = smallest[comp[own]]


def _solve_and_cut(robot: Robot, lab: int, round_: int) -> None:
    cut_own_side(robot, solve_set(robot.evidence.bundles[lab]), round_)


def run_evidence_resolution(robots: list[Robot], network: Transport,
                            max_rounds: int | None = None, on_round=None) -> dict:
    """One flood-and-solve pass on all robots (the driver only plays the clock).

    A robot with an empty inbox has nothing to keep, forward or solve (its sets are solved
    when their last bundle arrives), so each round steps only the robots with a message
    (all of them on a transport that cannot tell).

    Returns ``rounds`` and ``conflictive_sets`` (sets, counted at their smallest robot).
    """
    sends = [partial(network.send, rb.id) for rb in robots]
    touched = [start_evidence(rb, sends[rb.id]) for rb in robots]
    cap = max_rounds if max_rounds is not None else len(robots) + 2
    t = 0
    while network.pending:
        network.end_round()
        t += 1
        if on_round is not None:
            on_round(t)
        receivers = network.receivers() if hasattr(network, "receivers") else range(len(robots))
        for i in receivers:
            evidence_step(robots[i], network.inbox(i), sends[i], t)
        if t > cap:
            raise StageStalledError(f"evidence resolution did not end within {cap} rounds")
    unsolved = [rb.id for rb in robots if set(rb.evidence.bundles) - rb.evidence.solved]
    labels = set()
    for rb in robots:
        labels.update(rb.evidence.bundles)
    return finish_evidence(robots, t, unsolved, len(labels), sum(1 for x in touched if x))


def evidence_pass(robots: list[Robot], network: Transport, protocol=None, iteration: int = 0,
                  on_round=None) -> dict:
    """The ``evidence`` rule's pass in the simulator (:mod:`pipeline.consistency.rules`):
    :func:`run_evidence_resolution`; the rule needs no protocol object or iteration number."""
    return run_evidence_resolution(robots, network, on_round=on_round)


def reexamine_sets(robot: Robot) -> None:
    """After a pass: the next detection examines the robot's sets again (the solved ones are
    conflict-free then)."""
    robot.candidates = robot.conflictive.copy()


def finish_evidence(robots: list[Robot], rounds: int, unsolved: list[int], n_sets: int,
                    robots_in_sets: int) -> dict:
    """End of a pass: an error if some robot lacks part of a set, else every robot's next
    detection re-examines its solved sets; returns ``rounds``, ``conflictive_sets`` and
    ``robots_in_sets``."""
    if unsolved:
        raise RuntimeError(f"robots {unsolved} did not receive their whole conflictive set")
    for rb in robots:
        reexamine_sets(rb)
    return dict(rounds=rounds, conflictive_sets=n_sets, robots_in_sets=robots_in_sets)


# --------------------------------------------------------------------------- one robot alone


def _set_neighbours(robot: Robot) -> set[int]:
    st: EvidenceState = robot.evidence
    return set().union(*st.set_nbrs.values()) if st.set_nbrs else set()


def start_evidence_reliable(robot: Robot, rel, now: int) -> int:
    """Round 0 of the rule run by a robot alone (its own process): bundles over the reliable
    channel of ``rel`` (a :class:`~.reliable.ReliableState`); returns its conflictive sets.

    With no driver to end the flood when nothing is in flight, each robot ends the phase by
    the termination wave of :mod:`.termination` with :func:`evidence_done` as its *done*
    predicate. The bundles and the solution are those of :func:`start_evidence` and
    :func:`evidence_step`, so every robot cuts what it cuts in the simulator.
    """
    rel.lost_in_phase = False
    return start_evidence(robot, lambda dst, kind, p: rel.chan.send(dst, kind, p, now))


def evidence_round(robot: Robot, rel, inbox: list[Message], now: int, phase_round: int) -> None:
    """One network round of the rule for a robot alone (see :func:`start_evidence_reliable`).

    Bundles arrive through the reliable channel (acknowledged, delivered once). A robot hears
    every neighbour it shares a conflictive set with at least every ``heartbeat_every``
    rounds (heartbeats), so a neighbour silent for ``loss_timeout`` rounds has crashed: it is
    declared lost and its links are cut (``robot-lost``), as in the reliable Alg. 1.
    """
    from pipeline.consistency.reliable import cut_lost, measure_state

    chan = rel.chan
    msgs = [m for m in chan.receive(inbox, now) if m.kind == "bundle"]
    nbrs = _set_neighbours(robot) - chan.lost
    lost = chan.check_lost(now, nbrs)
    if lost:
        cut_lost(robot, rel, lost, phase_round)
    evidence_step(robot, msgs, lambda dst, kind, p: chan.send(dst, kind, p, now), phase_round)
    chan.flush(now, heartbeat_to=sorted(nbrs - chan.lost))
    measure_state(robot, rel)


def evidence_done(robot: Robot, rel, lost_somewhere: bool) -> bool:
    """The *done* predicate of the rule for a robot alone.

    Done when every bundle it sent is acknowledged and either every conflictive set it takes
    part in is solved, or some robot of the team declared a neighbour lost in this phase
    (``lost_somewhere``: its own loss or the wave's bit). A set is solved only from all its
    bundles, so a robot that cut its side of a link has forwarded to the other end, before
    being done, every bundle that end lacked: the other end solves the same set alike (cuts
    stay symmetric). A set that lost a robot before all its bundles were out is never
    complete; its robots stop waiting once the loss is known, cut nothing in it, and the
    detection that follows (repeated after a loss, :mod:`.termination`) finds it again
    without the lost robot.
    """
    st: EvidenceState = robot.evidence
    if not rel.chan.idle():
        return False
    return lost_somewhere or rel.lost_in_phase or not (set(st.bundles) - st.solved)
