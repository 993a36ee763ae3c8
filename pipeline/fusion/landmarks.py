"""Robust distributed fusion of every track's landmark by dynamic voting (pipeline stage).

For each track (association set of the kept links: a connected component with at least two
features) every robot that observes it
forms a local 3D estimate of the landmark and the observers fuse these estimates by dynamic
voting (Montijano et al., Sec. IV-B): by default at its consensus limit, computed by each
robot after flooding its track's observations (:mod:`pipeline.fusion.flooding`), or by the
paper's Metropolis iteration (:func:`pipeline.fusion.voting.dynamic_voting`). A robot
whose estimate is voted out, and whose own keypoint does not reproject within the pixel gate
of the fused landmark, declares its observation an outlier; its links to the track's other
observations are cut with reason ``fusion-outlier`` — those that reach an observation not
declared an outlier, and those between two outliers that cannot be one point (below,
"Outliers leave the landmark").

The distributed model
---------------------
Tracks come from what each robot learnt in the consistency stage, not from a global
union-find: every robot names the track of each of its features itself
(:meth:`pipeline.consistency.robot.Robot.final_tracks`: its Alg. 1 component, or the smallest
feature id of its detection row), and tells its neighbours, with its keypoint, pose and
intrinsics, which track each of its observations belongs to (the setup message counted in
``setup_*``). Robot ``i`` takes part in track ``b`` with neighbour ``j`` exactly when both
named an observation ``b``; the keypoint of ``j`` it uses is the one ``j`` sent. A robot's
max-c draws in a track are a hash of the run's seed, the track's name and its own id
(:func:`pipeline.fusion.protocol.hypothesis_draws`), so a robot in its own process draws what
the simulator draws for it; the result's ``track_ids`` are renumbered like :func:`tracks_of`
for reporting only.

All tracks run at once on the flat node set of :mod:`pipeline.fusion.consensus`: node
``b * n + i`` is robot ``i`` in track ``b``; it is linked to node ``b * n + j`` when robots
``i`` and ``j`` are communication neighbours and both observe track ``b``. Robots that do not
observe a track take no part in its fusion. A robot needs only its own keypoint, pose and
intrinsics, and its neighbours' keypoints, poses and intrinsics for the track (one message
each, before the consensus: 2 + 12 + 4 reals, counted in ``setup_*`` stats).

Local estimate (``local=``)
---------------------------
* ``"robust"`` (default): the robot's own keypoint plus the largest set of its neighbours'
  keypoints that agree with it — for each observing neighbour the two-view point is
  triangulated, its support is the set of neighbours' keypoints that reproject within the
  pixel gate, and the best-supported set is triangulated together (a local RANSAC that always
  keeps the robot's own keypoint).
* ``"pair"``: two-view triangulation of the robot's own keypoint with the keypoint of the
  neighbour whose ray makes the widest angle with its own.
* ``"neighbours"``: multi-view triangulation of its own keypoint with the keypoints of *all*
  its neighbours in the track (the plain reading of the stage's description).

Why not ``neighbours``: estimates must differ for a vote to tell them apart. With it, every
robot of a complete communication graph (formation ``d``) triangulates the very same keypoint
set, so all estimates are equal and nothing is ever voted out (0 links cut on formation
``d``); on any graph a wrong keypoint contaminates the estimates of all its neighbours.
``pair`` spreads a wrong keypoint to the robots that chose it as partner — with the widest
angle, many robots choose the same end-of-row camera — and then cuts good observations (97
links cut, 52 of them good). ``robust`` keeps a wrong neighbour's keypoint out of a good
robot's estimate, while the robot holding the wrong keypoint must keep it and lands far from
the others (61 links cut, 60 of them spurious, of the 105 spurious links left by resolution).
These figures: ``python bench/voting_pipeline.py``, formation ``d`` rows (640x480, seed 0,
after the ``paper`` resolution, default keypoint noise and consensus). A robot voted out
keeps its observation when its own keypoint reprojects onto the fused landmark within the
gate.

Triangulation is linear (DLT on normalized coordinates, every row scaled to unit norm) and
then refined by three Gauss–Newton steps on the pixel reprojection error. The covariance is
the first-order propagation of isotropic keypoint noise ``σ_i``:
``Λ_i = σ_i² (Σ_v J_vᵀ J_v)⁻¹`` with ``J_v`` the ``2 × 3`` Jacobian of the projection into
view ``v`` at the estimate.

Keypoint noise (``noise=``)
---------------------------
``σ_i`` is robot ``i``'s own, measured before the consensus from the two-view residuals of
its tracks with its observing neighbours (:mod:`pipeline.fusion.noise`, ``"measured"``,
default): the Gaussian scale whose ``p``-quantile matches the exponential law fitted to its
residuals by their median, never below ``sigma_px`` (1 px). ``"fixed"``: ``σ_i = sigma_px``
for every robot. On Graffiti (complete graph), with an earlier version of the stage (before
the cut rule of "Outliers leave the landmark" below, and earlier matching defaults): fixed
1 px cut 67 good and 62 spurious links, the measured scales (1.0–1.6 px) 20 good and 41
spurious. The current stage, measured scales, cuts 6 good and 44 spurious there
(``python bench/graffiti_truth.py``, complete column); no command measures ``"fixed"`` on it
today (it is an argument of :func:`fuse_tracks` only). Formations a–d measure
0.10–0.15 px, so the floor holds and their cuts do not move.

Outliers leave the landmark
---------------------------
The paper discards an outlier observation from the landmark's estimate (Montijano et al.,
Sec. IV-B: the observations outside the winning hypothesis' gate); which links that cuts it
leaves open. Here an outlier leaves its landmark: a link is cut when exactly one of its ends
is an outlier, so the outliers' links to the landmark's other observations go; a link
between two outliers stays when the two can be one point — their two-view point in front
of both cameras and within the pixel gate of both keypoints at the team's noise floor
(:func:`pipeline.fusion.local.outlier_pair_tol`), or, without a baseline, the point at infinity along
their rays
(:func:`pipeline.fusion.local.pair_agrees`) — and is cut otherwise. What stays joins them in
a set of their own (a subset of a conflict-free set is conflict-free). Outliers linked to
each other are most often observations of one other point that a wrong link joined to this
track: the frames of a robot standing still, or a group of robots that saw one wrong point.
Cutting every link at an outlier (the earlier reading) cut their links to each other too,
which are right: ``run-formation --steps 3 --speed 0 --resolution sync`` cut 262 good and 455
spurious links that way; keeping every link between two outliers, 30 good and 442 spurious;
batch formations a–d under the evidence rule 2, 5, 7, 10 good links (23, 28, 48, 60
spurious) against 0, 0, 0, 1 (22, 27, 47, 59; ``run-formations --resolution evidence`` now
gives 0, 0, 0, 1 (22, 28, 47, 59)), Graffiti (``bench/graffiti_truth.py``, complete column)
10 good and 46 spurious against 6 and 44 (as in the README's Graffiti table). Keeping
every such link also kept pairs that are no point at all: on the rendered towers of repeated
windows (``bench/images_vs_colmap.py --rings-only --rings ABCD --ring-seeds 0,1,2 --methods
ours``) the wrong tracks of the reconstruction rose from 4, 5, 2
to 14, 20, 10; with the pair test 8, 9, 7 (1645, 1656, 1589 points against 1602, 1608, 1543
cutting every link, the pose errors within 0.01° and 1 mm). Each end of a link decides
alike: it knows whether its own observation is an outlier and is told its neighbour's
(``fusion-cut``, :class:`pipeline.fusion.robot.FusionRobot`), and it holds the neighbour's
keypoint and camera from the setup message, so it computes the pair test with the same bits.

Interpretations and limits
--------------------------
* The estimates of two neighbours that share keypoints are correlated; eq. (1) treats them as
  independent, so the fused covariance is optimistic. The fused point is still the
  information-weighted mean of the local estimates.
* Tracks that hold two features of one camera (conflictive sets, which resolution removes)
  are not fused: their observations are neither fused nor cut (``tracks_conflictive``).
* A track seen by two robots only is never cut: whatever ``local`` says, both robots
  triangulate the same two keypoints, so their estimates agree and both vote yes for every
  hypothesis (the paper's Condition 2 is "hard to be true" for 2–3 inliers, Sec. IV-C). A
  wrong link between the only two observers of a point is left as it is.
* A robot without an observing neighbour cannot triangulate; its observation is kept
  unverified (``estimated`` false). An estimate whose normal matrix is singular (parallel
  rays) is dropped the same way; the robot then only relays.
* The fused point of a track is the final ``θ_i`` averaged over the robots of the largest
  connected group of observers that picked the group's most common winner. Robots of one
  group agree up to consensus precision unless hypotheses tie in votes (a track chaining two
  surface points seen by equally many robots); such tracks are counted as
  ``tracks_split_winner``.
* The vote's gate is the usual chi-square test on the squared Mahalanobis distance
  (``gate="squared"``); the covariances here come from the measurement model with each
  robot's measured noise, so the test is calibrated to the robot's data (see
  ``bench/voting_table1.py`` for the readings of the paper's own gate). The pixel checks use
  the same test on the reprojection error: ``‖e‖² / σ_i² <= χ²_{2,p}``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.association import association_sets
from pipeline.commgraph import check_comm_edges
from pipeline.errors import InputError
from pipeline.fusion.consensus import (
    FixedTopology,
    SwitchingTopology,
    bundle_bytes,
    ransac_hypotheses,
)
from pipeline.fusion.flooding import exact_dynamic_voting
from pipeline.fusion.local import (
    TwoViewPoints,
    local_estimates,
    observing_neighbours,
    outlier_pair_tol,
    pair_agrees,
    project,
    two_view_points,
)
from pipeline.fusion.noise import NOISE_MODES, robot_noise
from pipeline.fusion.points import fused_points
from pipeline.fusion.protocol import (
    CountingExchange,
    LinkTraffic,
    LockstepExchange,
    hypothesis_draws,
)
from pipeline.fusion.robot import CUT, CUT_DTYPE
from pipeline.fusion.voting import (
    VOTE_TIE_TOL,
    RoundProtocol,
    chi2_ppf,
    dynamic_voting,
    gate_threshold,
)
from pipeline.transport import HEADER_BYTES, Transport
from pipeline.types import Features, Links, View

__all__ = ["FusionResult", "fuse_tracks", "require_posed_views", "tracks_of"]

LOCAL_MODES = ("robust", "pair", "neighbours")
CONSENSUS_MODES = ("exact", "metropolis")


@dataclass
class FusionResult:
    """Fused landmarks and the observations voted out.

    Attributes
    ----------
    points : ndarray, (T, 3)
        Fused landmark of each fused track (world frame).
    track_ids : ndarray, (T,) int
        Track of each point (tracks numbered by their smallest global feature id, as in
        :func:`tracks_of`).
    obs_track, obs_cam, obs_feat : ndarray, (O,) int
        Every observation (feature) of every track.
    obs_estimated : ndarray, (O,) bool
        The robot formed a local estimate and took part in the vote.
    obs_inlier : ndarray, (O,) bool
        Not declared an outlier (true also for observations that were not estimated).
    cut_links : ndarray, (L,) bool
        Links with exactly one end at an outlier observation, and links between two outliers
        that cannot be one point (to cut with reason ``fusion-outlier``; module docstring,
        "Outliers leave the landmark").
    obs_votes : ndarray, (O, K)
        The observing robot's final vote vector ``v_i`` for its track (NaN where the track
        was not fused): what decided its winner.
    obs_point : ndarray, (O,) int or None
        Row of ``points`` fused from the observation's track, ``-1`` when its track has no
        fused point: the features of point ``p`` are the observations with ``obs_point == p``
        (with ``track_labels`` a track is the robots' own, which ``obs_track`` does not name:
        tracks of the same ``track_ids`` may be several)
    stats : dict
        ``rounds`` (max-c + consensus), ``messages`` (robot-to-robot, one per neighbour pair
        and direction per round, bundling all shared tracks, then the ``fusion-cut`` notices
        of the robots that declared outliers), ``bytes``, and counts, among them
        ``observations_voted_out`` (estimates voted out of their track),
        ``observations_cut`` (observations *declared outliers*: voted out and not
        reprojecting within the gate of the fused landmark, i.e. ``~obs_inlier``; not the
        observations that lost a link: an outlier's links to the other outliers stay where
        the two can be one point, so an outlier may keep links; the name is kept for the
        reports that hold it) and ``links_cut`` (links cut ``fusion-outlier``; a run's
        ``fusion`` section also holds them as ``observations_cut_links`` and ``cut_links``).
    """

    points: np.ndarray
    track_ids: np.ndarray
    obs_track: np.ndarray
    obs_cam: np.ndarray
    obs_feat: np.ndarray
    obs_estimated: np.ndarray
    obs_inlier: np.ndarray
    cut_links: np.ndarray
    stats: dict = field(default_factory=dict)
    obs_votes: np.ndarray | None = None
    obs_point: np.ndarray | None = None


def tracks_of(features_per_camera, links: Links) -> tuple[np.ndarray, int]:
    """Track id of every feature (global index), ``-1`` outside tracks; and the track count.

    Tracks are the association sets (:func:`pipeline.association.association_sets`),
    numbered in order of their smallest global feature id.
    """
    track_of, tracks = association_sets(features_per_camera, links)
    return track_of, len(tracks)


def tracks_from_labels(track_labels, m_total: int) -> tuple[np.ndarray, int, np.ndarray]:
    """Track index of every feature from the robots' own track names (in name order), the
    track count and each track's name."""
    lab = np.asarray(track_labels, dtype=np.int64).reshape(-1)
    if lab.shape[0] != m_total:
        raise InputError(f"track_labels must have one entry per feature ({m_total}), got "
                         f"{lab.shape[0]}")
    track_of = np.full(m_total, -1, dtype=np.int64)
    valid = np.flatnonzero(lab >= 0)
    names, inv, counts = np.unique(lab[valid], return_inverse=True, return_counts=True)
    real = counts >= 2  # a name held by one feature only is no association set
    renum = np.cumsum(real) - 1
    keep = real[inv]
    track_of[valid[keep]] = renum[inv[keep]]
    return track_of, int(real.sum()), names[real]


# --------------------------------------------------------------------------------------------
# the stage


def require_posed_views(views, features) -> None:
    """InputError unless there is one feature set per view and every view has a pose."""
    n = len(views)
    if len(features) != n:
        raise InputError(f"got {len(views)} views but {len(features)} feature sets; one each")
    for i, v in enumerate(views):
        if v.R is None or v.t is None:
            raise InputError(f"view {i} ({v.name}) has no pose; fusion needs every camera's "
                             "cam_from_world (R, t)")


def _check_inputs(views, features, links, comm_edges, sigma_px, local, noise):
    require_posed_views(views, features)
    n = len(views)
    if not sigma_px > 0:
        raise InputError(f"sigma_px must be > 0, got {sigma_px}")
    if local not in LOCAL_MODES:
        raise InputError(f"local must be one of {LOCAL_MODES}, got {local!r}")
    if noise not in NOISE_MODES:
        raise InputError(f"noise must be one of {NOISE_MODES}, got {noise!r}")
    return check_comm_edges(comm_edges, n)  # (E, 2) as given: a flat list is refused, not paired


def _track_topology(edges_up, observes: np.ndarray, comm: np.ndarray, n: int):
    """Round ``t`` -> flat node edges ``b * n + i`` of every track over the comm edges up at ``t``.

    ``edges_up`` is the transport's :meth:`~pipeline.transport.Transport.edges`.
    """
    key = comm.min(1) * n + comm.max(1) if len(comm) else np.zeros(0, np.int64)
    per_edge = [np.flatnonzero(observes[:, i] & observes[:, j]) for i, j in comm]

    def edges(t: int) -> np.ndarray:
        up = np.sort(np.asarray(edges_up(t), dtype=np.int64).reshape(-1, 2), axis=1)
        sel = np.flatnonzero(np.isin(key, up[:, 0] * n + up[:, 1]))
        parts = [np.stack([per_edge[k] * n + comm[k, 0], per_edge[k] * n + comm[k, 1]], 1)
                 for k in sel]
        return np.concatenate(parts) if parts else np.zeros((0, 2), np.int64)

    return edges


def fuse_tracks(views: list[View], features: list[Features], links: Links, comm_edges,
                sigma_px: float = 1.0, *, local: str = "robust", p: float = 0.99,
                gate: str = "squared", p_in: float = 0.7, c: int = 1, success: float = 0.99,
                rounds: int = 100, seed: int = 0, transport: Transport | None = None,
                track_labels=None, wire: str = "float32", stop: bool = True,
                consensus: str = "exact", noise: str = "measured") -> FusionResult:
    """Fuse every track's landmark by dynamic voting; flag the observations voted out.

    Parameters
    ----------
    views : list of View, (n,) — poses ``R, t`` and intrinsics ``K`` are used
    features : list of Features, (n,)
    links : Links, (L,) — the kept links (one-to-one per camera pair)
    comm_edges : array_like, (E, 2) — communication graph
    sigma_px : float — keypoint noise (pixels) of the first-order covariances and the gates:
        with ``noise="measured"`` the floor of each robot's measured noise, with ``"fixed"``
        every robot's
    local : ``"robust"``, ``"pair"`` or ``"neighbours"`` — local estimate (module docstring)
    p, gate : chi-square gate of the vote (and of the reprojection check)
    p_in, c, success : RANSAC: number of hypotheses ``K`` (Sec. III)
    rounds : int — Metropolis consensus rounds (with ``stop``: the cap); the exact mode needs
        none (it closes each track at ``Diam + 1`` rounds, at most ``n``)
    seed : int — max-c draws: robot ``i``'s draws in a track are
        ``hypothesis_draws(seed, name, i)`` (:func:`pipeline.fusion.protocol.hypothesis_draws`,
        the track's name as the robots know it), so they do not depend on the other tracks
    transport : Transport or None
        The network the robots' messages travel on. ``None`` or a fault-free one: one
        network round per logical round. A faulty one (:attr:`~pipeline.transport.Transport.faulty`:
        loss, delay, crashes, a switching topology): every logical round is carried by the
        reliable channel in lockstep (:class:`~pipeline.fusion.protocol.LockstepExchange`),
        so the consensus is the fault-free one and a crashed robot leaves the graph once its
        neighbours declare it lost; its observations are not judged and its links not cut.
        Traffic is counted on the transport (kinds ``fusion-setup``, ``fusion-maxc``,
        ``fusion``, and ``fusion-cut``: the notices of the robots that declared outliers).
    wire : ``"float32"`` or ``"float64"`` — precision of the reals on the wire: the
        observations ``x_i``, ``Λ_i⁻¹`` of the exact mode's entries, the Metropolis state
        (float32 cut the same links as float64 on formations a–d and Sceaux, ``bench/fusion.py``)
    stop : bool
        ``True``: the ``consensus`` mode's own messages and end (Metropolis: per-link delta
        messages and the stop rule of :mod:`pipeline.fusion.protocol`, ``W = n − 1``).
        ``False``: the fixed-round Metropolis scheme (``rounds`` rounds, full float64 bundles
        on every edge every round, plain ``argmax`` winner) on the transport's per-round
        graph, whatever ``consensus`` says: the reference the others are compared with.
    noise : ``"measured"`` (default) or ``"fixed"``
        Each robot's keypoint noise ``σ_i`` measured from its own two-view residuals (floored
        at ``sigma_px``), or ``sigma_px`` for all (module docstring, :mod:`pipeline.fusion.noise`)
    consensus : ``"exact"`` or ``"metropolis"``
        ``"exact"`` (default): every track's observations are flooded over its observer
        graph and each robot computes the limit of max-c consensus and dynamic voting on its
        component (:mod:`pipeline.fusion.flooding`; ``Diam + 1`` rounds, votes as integer
        counts). ``"metropolis"``: the paper's Metropolis iteration (eqs. 2, 6, 11) with the
        stop rule of :mod:`pipeline.fusion.protocol` (``stop``) or fixed rounds.
    track_labels : array_like, (m_total,) int or None
        Each robot's own name for the track of each of its features, as it learnt it in the
        consistency stage (:meth:`pipeline.consistency.robot.Robot.final_tracks`; ``-1``
        outside tracks). Robots then fuse the tracks they know themselves, in the order of
        these names. ``None``: tracks by a union-find over ``links`` (for inputs that did not
        go through the consistency stage).

    Returns
    -------
    FusionResult

    Raises
    ------
    InputError
        A view without pose, mismatched views/features, bad links or comm edges.
    """
    comm = _check_inputs(views, features, links, comm_edges, sigma_px, local, noise)
    if consensus not in CONSENSUS_MODES:
        raise InputError(f"consensus must be one of {CONSENSUS_MODES}, got {consensus!r}")
    n = len(views)
    m = np.array([len(f) for f in features], dtype=np.int64)
    off = np.concatenate([[0], np.cumsum(m)])
    if track_labels is None:
        track_of, T = tracks_of(m, links)
        track_names = np.arange(T, dtype=np.int64)
    else:
        track_of, T, track_names = tracks_from_labels(track_labels, int(off[-1]))
    cam_of = np.repeat(np.arange(n), m)
    feat_of = np.arange(off[-1]) - off[cam_of]
    obs_g = np.flatnonzero(track_of >= 0)
    obs_track, obs_cam, obs_feat = track_of[obs_g], cam_of[obs_g], feat_of[obs_g]
    n_obs = len(obs_g)
    L = len(links)

    # (T, n) table of each track's feature per camera; tracks with two features of one camera
    # (conflictive) are left out
    per = np.zeros((T, n), dtype=np.int64)
    np.add.at(per, (obs_track, obs_cam), 1)
    conflictive = (per > 1).any(1)
    fused = ~conflictive
    table = np.full((T, n), -1, dtype=np.int64)
    ok_obs = fused[obs_track]
    table[obs_track[ok_obs], obs_cam[ok_obs]] = obs_feat[ok_obs]
    tr = np.flatnonzero(fused)
    tab = table[tr]                                                    # (B, n)
    B = len(tr)
    observes = tab >= 0
    adj = np.zeros((n, n), dtype=bool)
    adj[comm[:, 0], comm[:, 1]] = adj[comm[:, 1], comm[:, 0]] = True

    kp = np.zeros((B, n, 2))
    for i in range(n):  # per camera, vectorized over tracks
        sel = observes[:, i]
        kp[sel, i] = features[i].keypoints[tab[sel, i]].astype(np.float64)
    Rs = np.stack([np.asarray(v.R, dtype=np.float64) for v in views])
    ts = np.stack([np.asarray(v.t, dtype=np.float64).reshape(3) for v in views])
    Ks = np.stack([np.asarray(v.K, dtype=np.float64) for v in views])

    # pixel gate of the reprojection checks: squared error / σ_i² against χ²_{2,p}
    px_thr = chi2_ppf(p, 2)
    K = ransac_hypotheses(p_in, c, success)
    # each robot's keypoint noise σ_i, measured from its own two-view residuals (floor
    # sigma_px): the scale of its Λ_i = σ_i² (Σ J_vᵀ J_v)⁻¹, so of its chi-square vote
    # d(x_i, θ_i(t), Λ_i) <= χ²_{3,p} (eqs. 12–13), and of its pixel check below
    # (the two-view points of every observer pair, shared with the robust local estimate)
    # (the robot × robot work of both runs on a few tracks at a time, _track_chunks: a
    # track's rows depend on that track alone, so the chunks give the values of one call)
    node_edges, edge_link, active_comm = _observer_graph(comm, observes)
    chunks = _track_chunks(observes, node_edges)
    pairs = [two_view_points(kp[s], observing_neighbours(observes[s], adj), Rs, ts, Ks)
             if noise == "measured" else None for s in chunks]
    sigma, residuals = robot_noise(kp, observes, adj, Rs, ts, Ks, sigma_px, p, noise,
                                   pairs=_joined_pairs(pairs, chunks) if noise == "measured"
                                   else None)
    X = np.zeros((B, n, 3))
    cov = np.empty((B, n, 3, 3))
    estimated = np.zeros((B, n), dtype=bool)
    for s, pr in zip(chunks, pairs, strict=True):
        X[s], cov[s], estimated[s] = local_estimates(kp[s], observes[s], adj, Rs, ts, Ks, sigma,
                                                     px_thr, local, pairs=pr)
    # each robot's own max-c draws, from its id and the track's name (public once exchanged)
    draws = hypothesis_draws(seed, np.repeat(track_names[tr], n), np.tile(np.arange(n), B),
                             K).reshape(B, n, K)

    stats = dict(tracks=int(T), tracks_fused=0, tracks_conflictive=int(conflictive.sum()),
                 observations=int(n_obs), observations_estimated=int(estimated.sum()),
                 observations_voted_out=0, observations_cut=0, links_cut=0,
                 hypotheses=int(K), c=int(c), local=local, gate=gate, p=float(p),
                 sigma_px=float(sigma_px), noise=noise,
                 robot_sigma_px=[float(x) for x in sigma],
                 noise_residuals=[int(x) for x in residuals], rounds=0,
                 consensus_rounds=0,  # until the stage runs (no track: it does not)
                 maxc_rounds=0, messages=0, bytes=0, logical_messages=0,
                 # the mode that runs (or would have: no track), not the fixed scheme's
                 **({"consensus": consensus, "settled": True} if stop else {}))
    obs_track_out = obs_track
    if track_labels is not None:
        # reporting only: number the tracks like tracks_of (smallest feature id), the
        # contract of FusionResult; the robots never use this numbering
        uf, _ = tracks_of(m, links)
        obs_track_out = uf[obs_g]
    empty = FusionResult(np.zeros((0, 3)), np.zeros(0, np.int64), obs_track_out, obs_cam, obs_feat,
                         np.zeros(n_obs, bool), np.ones(n_obs, bool), np.zeros(L, bool), stats,
                         obs_point=np.full(n_obs, -1, dtype=np.int64))
    if B == 0 or not estimated.any():
        return empty

    protocol = None
    if stop:
        exchange = (LockstepExchange(transport, comm) if transport is not None
                    and transport.faulty else CountingExchange(len(comm)))
        # setup: each robot tells each neighbour its pose and intrinsics (12 + 4 float64)
        # and, per track it observes, the track's name (int64) and its keypoint (2 float32)
        n_obs_robot = observes.sum(0)
        src = np.stack([comm[:, 0], comm[:, 1]], 1).reshape(-1)
        exchange.round("fusion-setup", HEADER_BYTES + 16 * 8 + 16 * n_obs_robot[src])
        protocol = RoundProtocol(LinkTraffic(node_edges, edge_link, comm), n, n - 1, wire,
                                 exchange)
        # the exact mode floods over node_edges itself: no Metropolis weights to build
        maxc_rounds = n - 1
        topo = FixedTopology(node_edges, B * n) if consensus == "metropolis" else None
    elif transport is None or not transport.switching:
        topo, maxc_rounds = FixedTopology(node_edges, B * n), n - 1
    else:
        topo = SwitchingTopology(_track_topology(transport.edges, observes, comm, n), B * n)
        maxc_rounds = transport.window * (n - 1)
    if protocol is not None and consensus == "exact":
        res = exact_dynamic_voting(X, cov, estimated, observes, node_edges, edge_link,
                                   len(comm), K=K, c=c, thr=gate_threshold(3, p, gate),
                                   draws=draws, wire=wire, exchange=protocol.exchange)
    else:
        # the fixed-round scheme keeps its plain argmax: it is the reference as it ran before
        res = dynamic_voting(X, cov, topo, K=K, c=c, p=p, gate=gate, rounds=rounds,
                             observed=estimated, maxc_rounds=maxc_rounds, protocol=protocol,
                             tie_tol=VOTE_TIE_TOL if stop else 0.0, draws=draws)
    crashed = np.zeros(n, dtype=bool)
    if protocol is not None:
        protocol.exchange.finish()
        crashed[sorted(protocol.exchange.crashed)] = True
    voted_out = estimated & ~res.inlier
    # a robot voted out keeps its observation if its own keypoint reprojects onto the fused
    # landmark within the gate (‖e‖² / σ_i² <= χ²_{2,p}, its own noise): the fault was in its
    # partner's keypoint
    u, _, z = project(res.theta, Rs[None], ts[None], Ks[None], jacobian=False)
    e2 = ((u - kp) ** 2).sum(-1) / sigma[None, :] ** 2
    reproj_ok = res.valid & (z > 0) & (e2 <= px_thr)
    # a robot that crashed never finished: its observations are not judged
    outlier = voted_out & res.valid & ~reproj_ok & ~crashed[None]
    if protocol is not None:
        _cut_notices(protocol.exchange, comm, outlier.sum(0))
        # a robot that crashed while the notices went out never finished either: its
        # decision reached no one, so it is not judged and its links are not cut
        crashed[sorted(protocol.exchange.crashed)] = True
        outlier &= ~crashed[None]

    # fused point: largest connected group of observers per track, its most common winner
    # (a tie of votes between hypotheses can split a group; the split is counted in the stats)
    good = res.valid & estimated & ~crashed[None]    # a crashed robot's estimate is no part
    fused = fused_points(node_edges, good, res.theta, res.winner, K)
    pts, has_pt, grp, split = fused.points, fused.has_point, fused.group, fused.split

    obs_est, obs_in, obs_votes, cut, both = _observations_and_cuts(
        tr, T, obs_track, obs_cam, obs_g, off, links, estimated, outlier, crashed, res.votes, K)
    cut[both] = _apart(links, both, features, Rs, ts, Ks, outlier_pair_tol(sigma_px, px_thr))
    kinds = _stage_stats(stats, res, protocol, consensus, wire, node_edges, active_comm, crashed)
    stats.update(
        tracks_fused=int(has_pt.sum()), observations_voted_out=int(voted_out.sum()),
        observations_cut=int((~obs_in).sum()), links_cut=int(cut.sum()),
        tracks_split_winner=int((split & has_pt).sum()),
        max_disagreement=float(np.max(np.where(grp, np.linalg.norm(
            res.theta - pts[:, None], axis=-1), 0.0))) if has_pt.any() else 0.0)
    if transport is not None and protocol is None:
        transport.count("fusion-setup", stats["setup_messages"], stats["setup_bytes"])
        transport.count("fusion", stats["messages"], stats["bytes"])
    elif transport is not None and not transport.faulty:
        # (a lockstep exchange sent its packets through the transport itself)
        for kind, v in kinds.items():
            transport.count(kind, v["messages"], v["bytes"])
    point_of_track = np.full(T, -1, dtype=np.int64)
    point_of_track[tr[has_pt]] = np.arange(int(has_pt.sum()))
    obs_point = point_of_track[obs_track]
    if track_labels is not None:
        first_obs = np.full(T, -1, dtype=np.int64)
        first_obs[obs_track[::-1]] = obs_g[::-1]
        tr = uf[first_obs[tr]]
    return FusionResult(points=pts[has_pt], track_ids=tr[has_pt], obs_track=obs_track_out,
                        obs_cam=obs_cam, obs_feat=obs_feat, obs_estimated=obs_est,
                        obs_inlier=obs_in, cut_links=cut, stats=stats, obs_votes=obs_votes,
                        obs_point=obs_point)



#: robot × robot entries the local estimates work on at once (:func:`_track_chunks`)
CHUNK_ENTRIES = 1 << 22


def _track_chunks(observes, node_edges, cap: int = CHUNK_ENTRIES) -> list[slice]:
    """Consecutive runs of tracks whose local estimates work on at most about ``cap``
    robot × robot entries at once (a track alone if it needs more).

    The local estimates (:func:`pipeline.fusion.local.local_estimates`, the two-view points
    of :func:`pipeline.fusion.local.two_view_points`) hold per track dense ``(n, n)`` tables
    of the observing neighbours, their pairs and chosen views (``n²``), every keypoint of
    the track against the two-view point of each observing pair (``2 E_b n``, ``E_b`` the
    comm edges between its observers) and each estimate's triangulation over all ``n``
    cameras (``k_b n`` rows of some 64 entries' bytes, ``k_b`` its observers). Over all
    tracks at once that is ``O(B n²)``; chunk by chunk the peak is that of one chunk.
    """
    B, n = observes.shape
    edges = np.bincount(np.asarray(node_edges, dtype=np.int64).reshape(-1, 2)[:, 0] // max(n, 1),
                        minlength=B)
    cost = n * n + 2 * edges * n + 64 * observes.sum(1) * n
    chunks, start, acc = [], 0, 0
    for b, c in enumerate(cost.tolist()):
        if acc and acc + c > cap:
            chunks.append(slice(start, b))
            start, acc = b, 0
        acc += c
    if B:
        chunks.append(slice(start, B))
    return chunks


def _joined_pairs(pairs: list[TwoViewPoints], chunks: list[slice]) -> TwoViewPoints:
    """The two-view points of consecutive chunks of tracks as those of all the tracks."""
    if not pairs:
        return TwoViewPoints(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
                             np.zeros((0, 3)), np.zeros(0, dtype=bool))
    return TwoViewPoints(np.concatenate([pr.b + s.start for pr, s in zip(pairs, chunks, strict=True)]),
                         *(np.concatenate([getattr(pr, f) for pr in pairs])
                           for f in ("lo", "hi", "X", "ok")))


def _observer_graph(comm: np.ndarray, observes: np.ndarray):
    """The voting network: observers of a track linked by comm edges. Returns
    ``(node_edges (E, 2), edge_link (E,), active comm links)``, nodes ``track * n + robot``,
    ``edge_link`` the comm link of each edge."""
    n = observes.shape[1]
    node_edges, edge_link = [], []
    for k, (i, j) in enumerate(comm):
        b = np.flatnonzero(observes[:, i] & observes[:, j])
        node_edges.append(np.stack([b * n + i, b * n + j], 1))
        edge_link.append(np.full(len(b), k, dtype=np.int64))
    node_edges = np.concatenate(node_edges) if node_edges else np.zeros((0, 2), np.int64)
    edge_link = np.concatenate(edge_link) if edge_link else np.zeros(0, np.int64)
    active_comm = int(sum(bool((observes[:, i] & observes[:, j]).any()) for i, j in comm))
    return node_edges, edge_link, active_comm


def _observations_and_cuts(tr, T: int, obs_track, obs_cam, obs_g, off, links: Links, estimated,
                           outlier, crashed, votes, K: int):
    """Back from the fused tracks' rows to every observation and link: each observation's
    ``estimated``, ``inlier`` and votes; the links cut, those with exactly one end at an
    outlier observation (module docstring, "Outliers leave the landmark"; never a crashed
    robot's), and the indices of the links with both ends at outliers, which
    :func:`_apart` judges."""
    n_obs = len(obs_g)
    obs_est = np.zeros(n_obs, dtype=bool)
    obs_in = np.ones(n_obs, dtype=bool)
    pos_of_track = np.full(T, -1)
    pos_of_track[tr] = np.arange(len(tr))
    bo = pos_of_track[obs_track]
    sel = bo >= 0
    obs_est[sel] = estimated[bo[sel], obs_cam[sel]]
    obs_in[sel] = ~outlier[bo[sel], obs_cam[sel]]
    obs_votes = np.full((n_obs, K), np.nan)
    obs_votes[sel] = votes[bo[sel], obs_cam[sel]]
    bad_feature = np.zeros(off[-1], dtype=bool)
    bad_feature[obs_g[~obs_in]] = True
    # an outlier leaves its landmark: its links to the others go (two outliers: _apart)
    end_i = bad_feature[off[links.cam_i] + links.feat_i]
    end_j = bad_feature[off[links.cam_j] + links.feat_j]
    judged = ~(crashed[links.cam_i] | crashed[links.cam_j])
    return obs_est, obs_in, obs_votes, (end_i ^ end_j) & judged, \
        np.flatnonzero(end_i & end_j & judged)


def _apart(links: Links, k: np.ndarray, features, Rs, ts, Ks, tol_px: float) -> np.ndarray:
    """Whether each link ``k`` (between two outlier observations) joins two observations that
    cannot be one point (:func:`pipeline.fusion.local.pair_agrees`, within ``tol_px``, the
    lower camera first): cut with the outliers' other links (module docstring, "Outliers
    leave the landmark")."""
    if not len(k):
        return np.zeros(0, dtype=bool)
    lo = np.minimum(links.cam_i[k], links.cam_j[k])
    flip = links.cam_i[k] != lo
    fl = np.where(flip, links.feat_j[k], links.feat_i[k])
    fh = np.where(flip, links.feat_i[k], links.feat_j[k])
    hi = np.maximum(links.cam_i[k], links.cam_j[k])
    def keypoints(cams, feats):
        return np.stack([np.asarray(features[c].keypoints[f], np.float64)
                         for c, f in zip(cams.tolist(), feats.tolist(), strict=True)])

    uv = np.stack([keypoints(lo, fl), keypoints(hi, fh)], axis=1)
    two = np.stack([lo, hi], axis=1)
    return ~pair_agrees(uv, Rs[two], ts[two], Ks[two], tol_px)


def _cut_notices(exchange, comm: np.ndarray, outliers) -> None:
    """The decision's messages: a robot that declared ``outliers[i] > 0`` of its observations
    outliers tells each comm neighbour which features they are (kind ``fusion-cut``, the ids
    as :data:`~pipeline.fusion.robot.CUT_DTYPE`), so that the neighbour cuts its end of their
    links (:class:`pipeline.fusion.robot.FusionRobot` sends them, one to every neighbour still
    heard, after its decision); ``exchange`` carries them as one more round, drained."""
    k = np.asarray(outliers, dtype=np.int64)
    size = np.where(k > 0, HEADER_BYTES + np.dtype(CUT_DTYPE).itemsize * k, 0)
    sizes = np.stack([size[comm[:, 0]], size[comm[:, 1]]], 1).reshape(-1)
    if sizes.any():
        exchange.round(CUT, sizes)
        exchange.finish()


def _stage_stats(stats: dict, res, protocol, consensus: str, wire: str, node_edges,
                 active_comm: int, crashed) -> dict | None:
    """The stage's rounds, messages and bytes: counted by the exchange of the round protocol
    (returns its figures by message kind), or in bulk (fixed rounds; returns None)."""
    kinds = None
    setup_bytes = 2 * len(node_edges) * bundle_bytes(2 + 12 + 4, with_degree=False)
    total_rounds = res.maxc_stats.rounds + res.stats.rounds
    if protocol is not None:
        ex = protocol.exchange.summary()
        kinds = ex["by_kind"]
        stats.update(
            rounds=int(total_rounds), maxc_rounds=int(res.maxc_stats.rounds),
            consensus_rounds=int(res.stats.rounds), settled=bool(res.settled),
            consensus=consensus, gate_cycles=int(res.cycles or 0),
            stop_window=int(protocol.stop_window) if consensus == "metropolis" else None,
            wire=wire,
            network_rounds=int(ex["network_rounds"]), messages=int(ex["messages"]),
            bytes=int(ex["bytes"]), setup_messages=int(kinds["fusion-setup"].get("messages", 0)),
            setup_bytes=int(kinds["fusion-setup"].get("bytes", 0)),
            bytes_by_kind={k: int(v["bytes"]) for k, v in kinds.items() if "bytes" in v},
            logical_messages=int(2 * len(node_edges) * total_rounds),
            retransmissions=int(ex["retransmissions"]), dropped=int(ex["dropped"]),
            crashed=[int(i) for i in np.flatnonzero(crashed)],
            robots_lost={str(k): v for k, v in ex.get("robots_lost", {}).items()})
    else:
        stats.update(rounds=int(total_rounds), maxc_rounds=int(res.maxc_stats.rounds),
                     consensus_rounds=int(res.stats.rounds),
                     messages=int(2 * active_comm * total_rounds),
                     logical_messages=int(res.stats.messages + res.maxc_stats.messages),
                     bytes=int(res.stats.bytes + res.maxc_stats.bytes),
                     setup_messages=int(2 * len(node_edges)), setup_bytes=int(setup_bytes))
    return kinds
