"""The fusion stage's cut rule on small random rigs (pipeline.fusion.landmarks, "Outliers leave
the landmark"): a link is cut exactly when one of its ends is an observation declared an
outlier, or when both are and the two cannot be one point (pipeline.fusion.local.pair_agrees),
so the kept association stays conflict-free, and the robots one by one (on a fault-free or a
lossy network) cut the links the vectorized stage cuts."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from data_synth.formations import look_at
from pipeline.association import AssociationGraph, association_sets, count_conflicts
from pipeline.fusion.landmarks import fuse_tracks
from pipeline.fusion.local import outlier_pair_tol, pair_agrees
from pipeline.fusion.robot import FusionOptions, FusionRobot
from pipeline.fusion.robot_loops import run_fusion_locally, run_fusion_reliably
from pipeline.fusion.voting import chi2_ppf
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import NetworkOptions
from pipeline.types import Features, Links, View

K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])


def _rig(n: int, P: int, extra_edges, seed: int):
    """``n`` cameras in a row, a path comm graph plus ``extra_edges``, ``P`` points: each point
    is seen by a random subset of the cameras; in some tracks a group of cameras holds the
    keypoint of another point (a wrong link joined the groups), and some keypoints are off.
    Links join the features of a track on every comm edge between its observers. Returns
    views, features, links, comm edges and each camera's track names (the smallest global
    feature id of its association set, -1 outside one)."""
    rng = np.random.default_rng(seed)
    edges = {(i, i + 1) for i in range(n - 1)}
    edges |= {tuple(sorted(e)) for e in extra_edges if e[0] != e[1]}
    edges = np.array(sorted(edges), dtype=np.int64)
    pts = rng.uniform([-1, -1, 5], [1, 1, 7], (P, 3))
    other = pts + rng.uniform(0.4, 1.5, (P, 3)) * rng.choice([-1, 1], (P, 3))
    sees = rng.random((n, P)) < 0.8
    wrong = (rng.random((n, P)) < 0.3) & (rng.random(P) < 0.6)[None]  # group on Q in some tracks
    views, feats, feat_of = [], [], []
    for v in range(n):
        R, t = look_at([0.5 * v - 0.25 * n, 0.05 * v, 0.0], [0.0, 0.0, 6.0], up=(0.0, 1.0, 0.0))
        seen = rng.permutation(np.flatnonzero(sees[v]))
        X = np.where(wrong[v, seen, None], other[seen], pts[seen])
        p = (K @ (X @ R.T + t).T).T
        uv = p[:, :2] / p[:, 2:] + rng.normal(0, 0.2, (len(seen), 2))
        off = rng.random(len(seen)) < 0.1
        uv[off] += rng.choice([-1, 1], (int(off.sum()), 2)) * rng.uniform(10, 30, (int(off.sum()), 2))
        views.append(View(f"cam{v}", np.zeros((240, 320), np.uint8), K, R, t))
        feats.append(Features(uv.astype(np.float32), np.zeros((len(seen), 4), np.float32),
                              np.ones(len(seen), np.float32), "sift"))
        fo = np.full(P, -1)
        fo[seen] = np.arange(len(seen))
        feat_of.append(fo)
    ci, fi, cj, fj = [], [], [], []
    for a, b in edges.tolist():
        both = np.flatnonzero((feat_of[a] >= 0) & (feat_of[b] >= 0))
        ci += [a] * len(both)
        cj += [b] * len(both)
        fi += feat_of[a][both].tolist()
        fj += feat_of[b][both].tolist()
    links = Links(ci, fi, cj, fj)
    m = [len(f) for f in feats]
    names = np.full(sum(m), -1, dtype=np.int64)
    for s in association_sets(m, links)[1]:
        names[s] = s[0]                                  # sets come with ids ascending
    offs = np.concatenate([[0], np.cumsum(m)])
    labels = [names[offs[v]:offs[v + 1]] for v in range(n)]
    return views, feats, links, edges, labels


@settings(max_examples=25, deadline=None)
@given(n=st.integers(3, 6), P=st.integers(1, 6), seed=st.integers(0, 2**31 - 1),
       extra=st.lists(st.tuples(st.integers(0, 5), st.integers(0, 5)), max_size=4),
       consensus=st.sampled_from(["exact", "metropolis"]), lossy=st.booleans())
def test_a_link_is_cut_exactly_when_one_end_is_an_outlier(n, P, seed, extra, consensus, lossy):
    extra = [(a % n, b % n) for a, b in extra]
    views, feats, links, edges, labels = _rig(n, P, extra, seed)
    m = [len(f) for f in feats]
    off = np.concatenate([[0], np.cumsum(m)])
    fr = fuse_tracks(views, feats, links, edges, track_labels=np.concatenate(labels),
                     consensus=consensus)
    outlier = np.zeros(off[-1], dtype=bool)
    outlier[off[fr.obs_cam] + fr.obs_feat] = ~fr.obs_inlier
    end_a = outlier[off[links.cam_i] + links.feat_i]
    end_b = outlier[off[links.cam_j] + links.feat_j]
    cut = np.asarray(fr.cut_links, dtype=bool)
    # (a) no kept link joins an outlier and an observation that is not one
    assert not (~cut & (end_a != end_b)).any()
    # (b) every link between two observations that are not outliers is kept; one between two
    # outliers exactly when the two can be one point
    assert not (cut & ~end_a & ~end_b).any()
    both = np.flatnonzero(end_a & end_b)
    if len(both):
        Rs = np.stack([v.R for v in views]).astype(np.float64)
        ts = np.stack([np.asarray(v.t, np.float64).reshape(3) for v in views])
        Ks = np.stack([v.K for v in views]).astype(np.float64)
        ci, cj = links.cam_i[both], links.cam_j[both]   # cam_i < cam_j: the lower id first
        uv = np.stack([np.stack([feats[c].keypoints[f] for c, f in zip(ci, links.feat_i[both],
                                                                      strict=True)]),
                       np.stack([feats[c].keypoints[f] for c, f in zip(cj, links.feat_j[both],
                                                                      strict=True)])],
                      axis=1).astype(np.float64)
        two = np.stack([ci, cj], axis=1)
        agree = pair_agrees(uv, Rs[two], ts[two], Ks[two],
                            outlier_pair_tol(1.0, chi2_ppf(0.99, 2)))
        np.testing.assert_array_equal(cut[both], ~agree)
    assert fr.stats["links_cut"] == int(cut.sum())
    # (c) the kept association is conflict-free, as the input was
    assert count_conflicts(AssociationGraph(m, links)).conflictive_sets == 0
    assert count_conflicts(AssociationGraph(m, links.subset(~cut))).conflictive_sets == 0
    # (d) every robot, on its own, cuts its ends of the same links
    robots = [FusionRobot(i, n, edges, labels[i], feats[i].keypoints, views[i].K, views[i].R,
                          views[i].t, FusionOptions(consensus=consensus)) for i in range(n)]
    if lossy:
        team = LocalTeam(n, edges, NetworkOptions(drop_probability=0.2, seed=seed % 1000))
        outs = team.run(lambda end: run_fusion_reliably(robots[end.id], end))
    else:
        team = LocalTeam(n, edges)
        outs = team.run(lambda end: run_fusion_locally(robots[end.id], end))
    assert all(o["lost"] == [] for o in outs)
    for i, r in enumerate(robots):
        rows = np.flatnonzero((links.cam_i == i) | (links.cam_j == i))
        first = links.cam_i[rows] == i
        nbr = np.where(first, links.cam_j[rows], links.cam_i[rows])
        own = np.where(first, links.feat_i[rows], links.feat_j[rows])
        far = np.where(first, links.feat_j[rows], links.feat_i[rows])
        np.testing.assert_array_equal(r.cut_rows(nbr, own, far), cut[rows])
