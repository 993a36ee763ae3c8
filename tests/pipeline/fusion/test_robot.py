"""One robot's fusion (pipeline.fusion.robot): robots one by one equal the vectorized stage."""

import numpy as np
import pytest

from data_synth.formations import look_at
from pipeline.fusion.landmarks import fuse_tracks
from pipeline.fusion.protocol import hypothesis_draws
from pipeline.fusion.robot import FusionOptions, FusionRobot
from pipeline.fusion.robot_loops import run_fusion_locally, run_fusion_reliably
from pipeline.transport.local import LocalTeam
from pipeline.transport.simulated import NetworkOptions
from pipeline.types import Features, Links, View


def _ring_rig(n=6, P=40, seed=5, chord=True, noise=0.3):
    """``n`` cameras on a ring (and one chord) observing ``P`` points, each seen by a random
    subset; links join the features of one point on every comm edge; some keypoints planted
    off (wrong but consistent). Features are numbered per camera in a shuffled order, and
    each feature's track name is its point's id plus 1000 (names the robots agree on);
    ``noise``: the keypoints' Gaussian noise (pixels), one value or one per camera."""
    rng = np.random.default_rng(seed)
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    pts = rng.uniform([-1, -1, 4], [1, 1, 7], (P, 3))
    edges = [(i, i + 1) for i in range(n - 1)] + [(0, n - 1)] + ([(1, 4)] if chord else [])
    edges = np.array(sorted(tuple(sorted(e)) for e in edges))
    sees = rng.random((n, P)) < 0.7
    views, feats, feat_of, labels = [], [], [], []
    for v in range(n):
        R, t = look_at([0.6 * v - 1.5, 0.1 * v, 0.0], [0.0, 0.0, 5.5], up=(0.0, 1.0, 0.0))
        seen = rng.permutation(np.flatnonzero(sees[v]))
        p = (K @ (pts[seen] @ R.T + t).T).T
        uv = p[:, :2] / p[:, 2:] + rng.normal(0, np.broadcast_to(noise, (n,))[v], (len(seen), 2))
        bad = rng.random(len(seen)) < 0.08
        uv[bad] += rng.choice([-1, 1], (int(bad.sum()), 2)) * rng.uniform(15, 40, (int(bad.sum()), 2))
        views.append(View(f"cam{v}", np.zeros((240, 320), np.uint8), K, R, t))
        feats.append(Features(uv.astype(np.float32), np.zeros((len(seen), 4), np.float32),
                              np.ones(len(seen), np.float32), "sift"))
        fo = np.full(P, -1)
        fo[seen] = np.arange(len(seen))
        feat_of.append(fo)
        labels.append(seen + 1000)
    ci, fi, cj, fj = [], [], [], []
    for a, b in edges:
        both = np.flatnonzero((feat_of[a] >= 0) & (feat_of[b] >= 0))
        ci += [a] * len(both)
        cj += [b] * len(both)
        fi += feat_of[a][both].tolist()
        fj += feat_of[b][both].tolist()
    return views, feats, Links(ci, fi, cj, fj), edges, labels


def _robots(views, feats, edges, labels, consensus="exact"):
    n = len(views)
    return [FusionRobot(i, n, edges, labels[i], feats[i].keypoints, views[i].K, views[i].R,
                        views[i].t, FusionOptions(consensus=consensus)) for i in range(n)]


def _cuts(robots, links, feats):
    """The links the robots cut, each as its lower end decided it (``cut_rows``: one end an
    outlier and the other not, or two outliers that cannot be one point)."""
    out = np.zeros(len(links), dtype=bool)
    for i, r in enumerate(robots):
        mine = np.flatnonzero(links.cam_i == i)
        out[mine] = r.cut_rows(links.cam_j[mine], links.feat_i[mine], links.feat_j[mine])
    return out


@pytest.mark.parametrize("consensus", ["exact", "metropolis"])
@pytest.mark.parametrize("chord", [True, False])
def test_robots_one_by_one_equal_the_vectorized_stage(chord, consensus):
    views, feats, links, edges, labels = _ring_rig(chord=chord)
    ref = fuse_tracks(views, feats, links, edges, track_labels=np.concatenate(labels),
                      consensus=consensus)
    robots = _robots(views, feats, edges, labels, consensus)
    team = LocalTeam(len(views), edges)
    outs = team.run(lambda end: run_fusion_locally(robots[end.id], end))
    assert ref.cut_links.any()                         # the planted keypoints were cut
    np.testing.assert_array_equal(_cuts(robots, links, feats), ref.cut_links)
    # the same rounds (the wave floods the largest) and the same bytes of every kind
    assert {o["fusion_rounds"] for o in outs} == {ref.stats["rounds"]}
    counted = team.network.counters()["bytes_by_kind"]
    for kind, nbytes in ref.stats["bytes_by_kind"].items():
        assert counted[kind] == nbytes
    # every robot's end of a cut link knows it was cut (its own outlier or its neighbour's, not both)
    for i, r in enumerate(robots):
        mine = np.flatnonzero(links.cam_i == i)
        other = np.flatnonzero(links.cam_j == i)
        nbr = np.concatenate([links.cam_j[mine], links.cam_i[other]])
        own = np.concatenate([links.feat_i[mine], links.feat_j[other]])
        far = np.concatenate([links.feat_j[mine], links.feat_i[other]])
        np.testing.assert_array_equal(r.cut_rows(nbr, own, far),
                                      ref.cut_links[np.concatenate([mine, other])])


@pytest.mark.parametrize("consensus", ["exact", "metropolis"])
def test_the_stage_counts_the_robots_cut_notices(consensus):
    """Every message the robots send is counted by the vectorized stage, at its size: the
    ``fusion-cut`` notices too (a robot that declared outliers tells each neighbour which of
    its features they are, so that the neighbour cuts its end of the links)."""
    views, feats, links, edges, labels = _ring_rig()
    ref = fuse_tracks(views, feats, links, edges, track_labels=np.concatenate(labels),
                      consensus=consensus)
    robots = _robots(views, feats, edges, labels, consensus)
    team = LocalTeam(len(views), edges)
    team.run(lambda end: run_fusion_locally(robots[end.id], end))
    counted = team.network.counters()
    assert counted["messages_by_kind"]["fusion-cut"] > 0           # some robots cut
    assert ref.stats["bytes_by_kind"] == counted["bytes_by_kind"]
    assert (ref.stats["messages"], ref.stats["bytes"]) == \
        (sum(counted["messages_by_kind"].values()), sum(counted["bytes_by_kind"].values()))


@pytest.mark.parametrize("consensus", ["exact", "metropolis"])
def test_robots_measure_their_own_noise_as_the_stage_does(consensus):
    # keypoint noise above the 1 px floor, different per camera: every robot's σ_i, and so
    # its covariances, vote and pixel check, are the simulator's
    views, feats, links, edges, labels = _ring_rig(P=80, noise=[0.3, 2.0, 1.0, 3.0, 0.5, 2.5])
    ref = fuse_tracks(views, feats, links, edges, track_labels=np.concatenate(labels),
                      consensus=consensus)
    robots = _robots(views, feats, edges, labels, consensus)
    LocalTeam(len(views), edges).run(lambda end: run_fusion_locally(robots[end.id], end))
    assert [r.sigma for r in robots] == ref.stats["robot_sigma_px"]
    assert sum(s > 1.0 for s in ref.stats["robot_sigma_px"]) >= 3
    assert ref.cut_links.any()
    np.testing.assert_array_equal(_cuts(robots, links, feats), ref.cut_links)


@pytest.mark.parametrize("consensus", ["exact", "metropolis"])
def test_a_robot_crashed_during_fusion_leaves_the_graph_and_the_others_finish(consensus):
    views, feats, links, edges, labels = _ring_rig()
    robots = _robots(views, feats, edges, labels, consensus)
    # the fusion setup is round 1, then the flood (exact: Diam + 1 <= 4 rounds) or max-c
    # (metropolis: rounds 2-6): robot 3 crashes in the consensus
    team = LocalTeam(len(views), edges, NetworkOptions(crash_at={3: 3 if consensus == "exact"
                                                                  else 9}))
    outs = team.run(lambda end: run_fusion_locally(robots[end.id], end))
    assert outs[3] is None
    for i in (2, 4):  # its neighbours
        assert outs[i]["lost"] == [3]
    assert all(outs[i] is not None and robots[i].done for i in range(6) if i != 3)


def test_under_message_loss_the_reliable_lockstep_gives_the_fault_free_cuts():
    views, feats, links, edges, labels = _ring_rig()
    ref = fuse_tracks(views, feats, links, edges, track_labels=np.concatenate(labels))
    robots = _robots(views, feats, edges, labels)
    team = LocalTeam(len(views), edges, NetworkOptions(drop_probability=0.25, seed=4))
    outs = team.run(lambda end: run_fusion_reliably(robots[end.id], end))
    assert team.network.counters()["dropped"] > 0
    assert all(o["lost"] == [] for o in outs)
    assert sum(o["retransmissions"] for o in outs) > 0
    np.testing.assert_array_equal(_cuts(robots, links, feats), ref.cut_links)
    assert {o["fusion_rounds"] for o in outs} == {ref.stats["rounds"]}


def test_hypothesis_draws_depend_only_on_seed_name_robot():
    d = hypothesis_draws(7, [3, 3, 9], [0, 1, 0], 5)
    assert ((d > 0) & (d <= 1)).all()
    np.testing.assert_array_equal(hypothesis_draws(7, [9], [0], 5)[0], d[2])
    assert not np.array_equal(hypothesis_draws(8, [3], [0], 5)[0], d[0])
    assert len(np.unique(d)) == d.size
