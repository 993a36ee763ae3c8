import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.fusion.landmarks import fuse_tracks, tracks_of
from pipeline.fusion.local import local_estimates, triangulate_views
from pipeline.types import Links


def look_at(centre, target=(0.0, 0.0, 5.0)):
    z = np.asarray(target, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross([0.0, -1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ centre


def rig(n=4):
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    poses = [look_at(np.array([0.8 * k - 1.2, 0.1 * k, 0.0])) for k in range(n)]
    R = np.stack([p[0] for p in poses])
    t = np.stack([p[1] for p in poses])
    return R, t, np.broadcast_to(K, (n, 3, 3)).copy()


def project(X, R, t, K):
    p = (K @ ((R @ X[..., None])[..., 0] + t)[..., None])[..., 0]
    return p[..., :2] / p[..., 2:3]


def test_triangulation_exact_without_noise_and_first_order_covariance():
    R, t, K = rig(3)
    X = np.array([0.3, -0.2, 5.5])
    uv = np.stack([project(X, R[v], t[v], K[v]) for v in range(3)])
    mask = np.array([[True, True, False], [True, True, True]])
    Xs, cov, ok, rms = triangulate_views(np.stack([uv, uv]), mask, np.stack([R, R]),
                                         np.stack([t, t]), np.stack([K, K]), sigma_px=1.0)
    assert ok.all()
    assert np.allclose(Xs, X, atol=1e-9) and (rms < 1e-6).all()
    # more views, less uncertainty
    assert np.trace(cov[1]) < np.trace(cov[0])
    # first-order covariance against the spread of noisy solutions
    rng = np.random.default_rng(0)
    S = 3000
    noisy = uv[None, :2] + rng.normal(0, 1.0, (S, 2, 2))
    Xn, _, okn, _ = triangulate_views(noisy, np.ones((S, 2), bool), np.broadcast_to(R[:2], (S, 2, 3, 3)),
                                      np.broadcast_to(t[:2], (S, 2, 3)), np.broadcast_to(K[:2], (S, 2, 3, 3)))
    emp = np.cov(Xn[okn].T)
    assert np.allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(cov[0])), rtol=0.1)


def test_tracks_numbered_by_first_feature():
    links = Links(cam_i=[0, 1, 0], feat_i=[2, 0, 0], cam_j=[1, 2, 2], feat_j=[0, 1, 0])
    track_of, T = tracks_of([3, 2, 2], links)
    assert T == 2
    # track 0 holds feature (0,0) (global 0); track 1 holds (0,2),(1,0),(2,1)
    assert track_of.tolist() == [0, -1, 1, 1, -1, 0, 1]


def planted_rig():
    """4 cameras on a complete graph observing 30 points; camera 2's keypoint of point 7 is
    replaced by a keypoint of no point, 40 px away: wrong but consistent (no conflict)."""
    rng = np.random.default_rng(3)
    n, P = 4, 30
    R, t, K = rig(n)
    pts = rng.uniform([-1, -1, 4], [1, 1, 7], (P, 3))
    views, feats = [], []
    from pipeline.types import Features, View
    for v in range(n):
        uv = project(pts, R[v], t[v], K[v]) + rng.normal(0, 0.3, (P, 2))
        uv = np.concatenate([uv, [[20.0, 20.0]]])  # an extra feature: no point
        if v == 2:
            uv[P] = uv[7] + [40.0, 0.0]
        views.append(View(f"cam{v}", np.zeros((240, 320), np.uint8), K[v], R[v], t[v]))
        feats.append(Features(uv.astype(np.float32), np.zeros((P + 1, 4), np.float32),
                              np.ones(P + 1, np.float32), "sift"))
    ci, fi, cj, fj = [], [], [], []
    edges = np.array([(a, b) for a in range(n) for b in range(a + 1, n)])
    for a, b in edges:
        for k in range(P):
            ci.append(a)
            cj.append(b)
            fi.append(P if (a == 2 and k == 7) else k)
            fj.append(P if (b == 2 and k == 7) else k)
    return views, feats, Links(ci, fi, cj, fj), edges, pts


@pytest.mark.parametrize("local", ["robust", "pair"])
def test_fusion_cuts_planted_wrong_but_consistent_observation(local):
    views, feats, links, edges, pts = planted_rig()
    res = fuse_tracks(views, feats, links, edges, sigma_px=0.5, local=local)
    planted = ((links.cam_i == 2) & (links.feat_i == 30)) | ((links.cam_j == 2) & (links.feat_j == 30))
    assert res.cut_links[planted].all()
    assert not res.cut_links[~planted].any()
    assert res.stats["tracks_fused"] == 30 and res.stats["observations_cut"] == 1
    # the fused landmark of the planted track is still right
    k = int(np.flatnonzero(res.track_ids == 7)[0])
    assert np.linalg.norm(res.points[k] - pts[7]) < 0.05
    # all neighbours' estimates on a complete graph are the same keypoint set: nothing to vote
    same = fuse_tracks(views, feats, links, edges, sigma_px=0.5, local="neighbours")
    assert not same.cut_links.any()


def test_fusion_cuts_planted_link_on_rendered_formation():
    import data_synth
    from pipeline.evaluation.links import link_truth
    from pipeline.matching.features import extract_all
    from pipeline.matching.pairs import match_edges

    f = data_synth.render("d", seed=0, size=(320, 240))
    feats = extract_all(f.views)
    links = Links.from_matches(match_edges(feats, f.views, f.comm_edges))
    truth = link_truth(f, feats, links)
    links, truth = links.subset(truth), truth[truth]  # start from good links only
    m = [len(x) for x in feats]
    off = np.concatenate([[0], np.cumsum(m)])
    track_of, T = tracks_of(m, links)
    cam_of = np.repeat(np.arange(len(m)), m)
    # a track seen by >= 5 cameras; rewire one observation to a far, unlinked feature
    sizes = np.bincount(track_of[track_of >= 0], minlength=T)
    b = int(np.flatnonzero(sizes >= 5)[0])
    members = np.flatnonzero(track_of == b)
    g = members[2]
    k, r = int(cam_of[g]), int(g - off[cam_of[g]])
    xy = feats[k].keypoints
    free = np.flatnonzero(track_of[off[k]:off[k + 1]] < 0)
    far = free[np.linalg.norm(xy[free] - xy[r], axis=1) > 40]
    r2 = int(far[np.argmin(np.linalg.norm(xy[far] - xy[r], axis=1))])
    fi, fj = links.feat_i.copy(), links.feat_j.copy()
    fi[(links.cam_i == k) & (fi == r)] = r2
    fj[(links.cam_j == k) & (fj == r)] = r2
    planted = ((links.cam_i == k) & (fi == r2)) | ((links.cam_j == k) & (fj == r2))
    assert planted.sum() >= 2
    wrong = Links(links.cam_i, fi, links.cam_j, fj)
    res = fuse_tracks(f.views, feats, wrong, f.comm_edges)
    assert res.cut_links[planted].all()
    assert res.cut_links[~planted].mean() < 0.05


def test_fusion_inputs_are_checked():
    views, feats, links, edges, pts = planted_rig()
    with pytest.raises(InputError, match="sigma_px"):
        fuse_tracks(views, feats, links, edges, sigma_px=0)
    views[1].R = None
    with pytest.raises(InputError, match="no pose"):
        fuse_tracks(views, feats, links, edges)


def test_tracks_from_robot_names_equal_the_union_find_tracks():
    """Named by their smallest feature id, the robots' tracks give the union-find's result;
    any other names give the same tracks (renumbered like tracks_of in the output)."""
    views, feats, links, edges, _ = planted_rig()
    m = [len(f) for f in feats]
    ref = fuse_tracks(views, feats, links, edges, sigma_px=0.5)
    track_of, T = tracks_of(m, links)
    off = np.concatenate([[0], np.cumsum(m)])
    first = np.full(T, np.iinfo(np.int64).max)
    np.minimum.at(first, track_of[track_of >= 0], np.flatnonzero(track_of >= 0))
    names = np.where(track_of >= 0, first[track_of], -1)
    same = fuse_tracks(views, feats, links, edges, sigma_px=0.5, track_labels=names)
    assert np.array_equal(same.cut_links, ref.cut_links)
    assert np.array_equal(same.track_ids, ref.track_ids)
    assert np.array_equal(same.obs_track, ref.obs_track)
    assert np.allclose(same.points, ref.points)
    # other names (e.g. an Alg. 1 component id), one singleton name: still the same tracks
    other = np.where(names >= 0, off[-1] - names, -1)
    other[int(off[1])] = 10**6 if names[int(off[1])] < 0 else other[int(off[1])]
    res = fuse_tracks(views, feats, links, edges, sigma_px=0.5, track_labels=other)
    assert res.stats["tracks"] == ref.stats["tracks"]
    assert sorted(res.track_ids.tolist()) == sorted(ref.track_ids.tolist())
    assert np.array_equal(res.obs_track, ref.obs_track)


@pytest.mark.parametrize("local", ["robust", "pair", "neighbours"])
def test_local_estimates_of_all_robots_equal_each_robot_alone(local):
    # robots of one track that pick the same views share one triangulation in the
    # simulator; each row must still be exactly what the robot computes on its own
    rng = np.random.default_rng(11)
    n, B = 5, 40
    R, t, K = rig(n)
    X = rng.uniform([-1, -1, 4], [1, 1, 6], (B, 3))
    kp = project(X[:, None], R[None], t[None], K[None]) + rng.normal(0, 0.3, (B, n, 2))
    off = rng.random((B, n)) < 0.15
    kp[off] += rng.uniform(10, 30, (int(off.sum()), 2))
    observes = rng.random((B, n)) < 0.8
    adj = ~np.eye(n, dtype=bool)
    adj[0, 4] = adj[4, 0] = False
    all_X, all_cov, all_est = local_estimates(kp, observes, adj, R, t, K, 1.0, 9.21, local)
    assert all_est.sum() > B  # tracks with several estimating robots
    for i in range(n):
        X_i, cov_i, est_i = local_estimates(kp, observes, adj, R, t, K, 1.0, 9.21, local,
                                            robots=np.arange(n) == i)
        np.testing.assert_array_equal(all_est[:, i], est_i[:, i])
        np.testing.assert_array_equal(all_X[:, i], X_i[:, i])
        np.testing.assert_array_equal(all_cov[:, i], cov_i[:, i])


def test_without_a_track_no_round_is_counted():
    """No link, no track: the stage runs no round, and says so alike in its total and its
    consensus part (the report once showed 0 rounds of which 100 of consensus)."""
    views, feats, links, edges, _ = planted_rig()
    none = links.subset(np.zeros(len(links), dtype=bool))
    res = fuse_tracks(views, feats, none, edges, sigma_px=0.5)
    assert res.stats["tracks"] == 0
    assert res.stats["rounds"] == res.stats["consensus_rounds"] == res.stats["maxc_rounds"] == 0
    ran = fuse_tracks(views, feats, links, edges, sigma_px=0.5)
    assert ran.stats["rounds"] == ran.stats["maxc_rounds"] + ran.stats["consensus_rounds"] > 0


def test_comm_edges_not_of_shape_e_by_2_are_refused_not_paired_anew():
    # a flat list or a (2, E) array was reshaped to (E, 2): other pairs than those meant
    views, feats, links, edges, pts = planted_rig()
    e = np.asarray(edges)
    for wrong in (e.reshape(-1), e.T):
        with pytest.raises(InputError, match=rf"communication edges must have shape \(E, 2\), "
                                             rf"got \({wrong.shape[0]},"):
            fuse_tracks(views, feats, links, wrong)


@pytest.mark.parametrize("local", ["robust", "pair", "neighbours"])
def test_a_track_of_two_observers_is_never_cut(local):
    """Module docstring: the two robots of a two-observer track triangulate the same two
    keypoints, so a wrong link between them (camera 2's keypoint 40 px off) stays."""
    views, feats, links, edges, _ = planted_rig()
    two = (links.cam_i == 0) & (links.feat_i == 7) & (links.cam_j == 2)
    other = (links.feat_i == 7) | (links.feat_j == 7) | (links.feat_i == 30) | (links.feat_j == 30)
    keep = two | ~other
    kept = Links(links.cam_i[keep], links.feat_i[keep], links.cam_j[keep], links.feat_j[keep])
    res = fuse_tracks(views, feats, kept, edges, sigma_px=0.5, local=local)
    assert not res.cut_links[two[keep]].any()
    assert res.stats["observations_voted_out"] == 0
