"""Centralized multi-way matching baselines: permutation synchronization and CLEAR-style."""

from pathlib import Path

import numpy as np
import pytest
from consistency_graphs import instances
from hypothesis import HealthCheck, given, settings

from pipeline.commgraph import comm_graph
from pipeline.consistency import spectral
from pipeline.consistency.centralized import clear_kept, is_conflict_free, spectral_sync_kept
from pipeline.consistency.spectral import (
    clear_sync,
    labels_to_kept,
    spectral_sync,
    universe_size_count,
    universe_size_gap,
)
from pipeline.inputs.landmarks import load_landmark_folder
from pipeline.matching.landmarks import match_landmark_edges
from pipeline.types import Links

METHODS = [spectral_sync, clear_sync]
HOTEL_SMALL = Path(__file__).resolve().parents[2] / "data" / "cmu_hotel_small"


def truth_links(point, pairs_of_cameras):
    """Links of every feature pair imaging one point on the given camera pairs.

    ``point[i]``: (m_i,) the point of each feature of camera ``i`` (-1: none)."""
    ci, fi, cj, fj = [], [], [], []
    for i, j in pairs_of_cameras:
        for r, p in enumerate(point[i]):
            s = np.flatnonzero(point[j] == p)
            if p >= 0 and s.size:
                ci.append(i), fi.append(r), cj.append(j), fj.append(int(s[0]))
    return ci, fi, cj, fj


def complete(n):
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


def same_partition(labels, truth) -> bool:
    """Both group the features the same way (labels up to renaming; -1 = alone)."""
    def groups(lab):
        lab = np.asarray(lab)
        return {frozenset(np.flatnonzero(lab == v).tolist()) for v in np.unique(lab[lab >= 0])
                if (lab == v).sum() > 1}
    return groups(labels) == groups(truth)


def consistent(fpc, labels) -> bool:
    cam = np.repeat(np.arange(len(fpc)), fpc)
    lab = np.asarray(labels)
    on = lab >= 0
    keys = cam[on] * (lab.max() + 2 if on.any() else 1) + lab[on]
    return np.unique(keys).size == keys.size


def shuffled_cameras(n, k, seed):
    """Each camera sees the ``k`` points in its own random order."""
    rng = np.random.default_rng(seed)
    return [rng.permutation(k) for _ in range(n)]


# ------------------------------------------------------------------------ by hand


@pytest.mark.parametrize("method", METHODS)
def test_swapped_link_is_undone(method):
    # 4 cameras x 3 points, every pair matched; cameras 0-1 swap two of their matches
    point = shuffled_cameras(4, 3, seed=1)
    ci, fi, cj, fj = truth_links(point, complete(4))
    first = [t for t, (i, j) in enumerate(zip(ci, cj, strict=True)) if (i, j) == (0, 1)]
    a, b = first[0], first[1]
    fj[a], fj[b] = fj[b], fj[a]
    links = Links(ci, fi, cj, fj)
    truth = np.concatenate(point)
    for k in (None, 3):
        labels = method([3, 3, 3, 3], links, universe_size=k)
        assert same_partition(labels, truth)
        kept = labels_to_kept([3, 3, 3, 3], links, labels)
        assert kept.tolist() == [t not in (a, b) for t in range(len(links))]


@pytest.mark.parametrize("method", METHODS)
def test_missing_link_is_restored(method):
    point = shuffled_cameras(4, 3, seed=2)
    ci, fi, cj, fj = truth_links(point, complete(4))
    links = Links(ci[1:], fi[1:], cj[1:], fj[1:])                 # one good link dropped
    labels = method([3, 3, 3, 3], links)
    assert same_partition(labels, np.concatenate(point))
    assert labels[ci[0] * 3 + fi[0]] == labels[cj[0] * 3 + fj[0]]


@pytest.mark.parametrize("method", METHODS)
def test_partial_visibility_and_universe_estimate(method):
    # 6 cameras, 5 points, each camera sees 4 of them; one wrong link joins two points
    rng = np.random.default_rng(3)
    point = []
    for i in range(6):
        seen = np.delete(np.arange(5), i % 5)
        point.append(rng.permutation(seen))
    ci, fi, cj, fj = truth_links(point, complete(6))
    r0 = int(np.flatnonzero(point[0] == 1)[0])
    s2 = int(np.flatnonzero(point[2] == 3)[0])
    links = Links(ci + [0], fi + [r0], cj + [2], fj + [s2])
    labels = method([4] * 6, links)
    assert same_partition(labels, np.concatenate(point))
    assert np.unique(labels[labels >= 0]).size == 5


@pytest.mark.parametrize("method", METHODS)
def test_link_weights_decide(method):
    # camera 0's feature 0 is linked to both features of camera 1; the heavier link wins
    links = Links([0, 0], [0, 0], [1, 1], [0, 1])
    for w, partner in (([1.0, 0.1], 0), ([0.1, 1.0], 1)):
        labels = method([1, 2], links, np.array(w))
        assert labels[0] >= 0 and labels[0] == labels[1 + partner]
        assert labels[2 - partner] != labels[0]


def test_weak_features_left_unassigned_unless_asked():
    # 6 cameras see 3 points; a 7th camera's one feature is linked to each point twice, so
    # a third of its embedding's energy lies on each: cosine about 0.58 < 1/sqrt(2)
    point = shuffled_cameras(6, 3, seed=7)
    ci, fi, cj, fj = truth_links(point, complete(6))
    for cam in range(6):
        ci.append(cam), fi.append(int(np.flatnonzero(point[cam] == cam // 2)[0]))
        cj.append(6), fj.append(0)
    links, fpc = Links(ci, fi, cj, fj), [3] * 6 + [1]
    truth = np.concatenate(point + [np.array([-1])])
    labels = spectral_sync(fpc, links)
    assert labels[-1] == -1 and same_partition(labels, truth)
    plain = spectral_sync(fpc, links, min_cosine=-1.0)
    assert plain[-1] >= 0 and (plain[:-1] == labels[:-1]).all()
    assert clear_sync(fpc, links)[-1] >= 0                     # CLEAR assigns every feature


def test_universe_size_rules():
    # clean spectrum of a consistent complete association: 0 per point, 1 elsewhere
    mu = np.array([1.0, 1.0, 1.0, 0.0, 0.0])
    assert universe_size_count(mu, k_min=2) == 3
    assert universe_size_count(mu, k_min=4) == 4               # never below k_min
    lam_noisy = np.array([0.0, 0.02, 0.05, 0.03, 0.6])         # one component: 0 first
    assert universe_size_gap(1.0 - np.sort(lam_noisy), k_min=2) == 4
    # a long clean chain: small but nonzero modes after its 0 - the ratio keeps one point
    assert universe_size_gap(1.0 - np.array([0.0, 0.02, 0.08, 0.18, 0.32, 0.5]), 1) == 1


def test_clean_chains():
    # 12 cameras on a seq:2 graph, 5 points each: 5 components, each a chain of 12 cameras
    point = shuffled_cameras(12, 5, seed=4)
    pairs = [(i, j) for i in range(12) for j in range(i + 1, min(i + 3, 12))]
    links = Links(*truth_links(point, pairs))
    truth = np.concatenate(point)
    # the ratio gap sees one point per chain (a chain's modes after its 0 are no gap)
    assert same_partition(spectral_sync([5] * 12, links), truth)
    # CLEAR's count of eigenvalues below 0.5 counts a chain's slow modes as points too: it
    # splits each chain, never joining two points
    labels = clear_sync([5] * 12, links)
    assert np.unique(labels).size > 5
    assert all(np.unique(truth[labels == v]).size == 1 for v in np.unique(labels))


@pytest.mark.parametrize("method", METHODS)
def test_no_links_and_isolated_features(method):
    assert method([2, 3], Links([], [], [], [])).tolist() == [-1] * 5
    assert method([], Links([], [], [], [])).size == 0
    labels = method([2, 2], Links([0], [1], [1], [0]))
    assert labels[0] == labels[3] == -1 and labels[1] == labels[2] >= 0


@pytest.mark.parametrize("method", METHODS)
def test_bad_inputs(method):
    links = Links([0], [0], [1], [0])
    with pytest.raises(ValueError):
        method([1, 1], links, np.array([-1.0]))
    with pytest.raises(ValueError):
        method([1, 1], links, np.array([1.0, 1.0]))
    with pytest.raises(ValueError):
        method([1, 1], Links([0], [0], [1], [1]))
    with pytest.raises(ValueError):
        method([1, 1], links, universe_size=0)


@pytest.mark.parametrize("method", METHODS)
def test_sparse_solver_agrees_with_dense(method, monkeypatch):
    # 16 cameras x 8 points, every pair matched, every 9th pair with two matches swapped
    n, k = 16, 8
    point = shuffled_cameras(n, k, seed=5)
    ci, fi, cj, fj = truth_links(point, complete(n))
    for t in range(0, len(ci) - 1, 9 * k):
        fj[t], fj[t + 1] = fj[t + 1], fj[t]
    links = Links(ci, fi, cj, fj)
    fpc, truth = [k] * n, np.concatenate(point)
    monkeypatch.setattr(spectral, "DENSE_MAX", 10**6)
    assert same_partition(method(fpc, links), truth)
    monkeypatch.setattr(spectral, "DENSE_MAX", 40)             # ARPACK, then dense values
    assert same_partition(method(fpc, links), truth)
    monkeypatch.setattr(spectral, "DENSE_VALUES_MAX", 40)      # ARPACK windows doubling
    assert same_partition(method(fpc, links), truth)


def test_long_chains_every_solver_path(monkeypatch):
    # 3 points, each a chain of 60 cameras (seq:2): the estimates need many eigenvalues of
    # each 60-feature component, past a first ARPACK window once DENSE_MAX is lowered
    point = shuffled_cameras(60, 3, seed=6)
    pairs = [(i, j) for i in range(60) for j in range(i + 1, min(i + 3, 60))]
    links = Links(*truth_links(point, pairs))
    fpc, truth = [3] * 60, np.concatenate(point)
    runs = []
    for dense_max, values_max in ((10**6, 10**6), (40, 10**6), (40, 40)):
        monkeypatch.setattr(spectral, "DENSE_MAX", dense_max)
        monkeypatch.setattr(spectral, "DENSE_VALUES_MAX", values_max)
        assert same_partition(spectral_sync(fpc, links), truth)
        runs.append(clear_sync(fpc, links))
    assert np.unique(runs[0]).size > 3                         # CLEAR splits the chains
    assert all(same_partition(r, runs[0]) for r in runs[1:])


# ---------------------------------------------------------------------- properties


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances(max_n=6, max_feat=4))
def test_consistent_by_construction(inst):
    fpc, _, links = inst
    weight = links.quality
    for method in METHODS:
        for k in (None, 2):
            labels = method(fpc, links, weight, universe_size=k)
            assert labels.shape == (int(np.sum(fpc)),) and labels.dtype == np.int64
            assert (labels >= -1).all()
            assert consistent(fpc, labels)
            kept = labels_to_kept(fpc, links, labels)
            assert is_conflict_free(fpc, links.subset(kept))
            linked = np.zeros(labels.size, dtype=bool)
            off = np.concatenate([[0], np.cumsum(fpc)])
            linked[off[links.cam_i] + links.feat_i] = True
            linked[off[links.cam_j] + links.feat_j] = True
            assert (labels[~linked] == -1).all()


# -------------------------------------------------------------------- real frames


@pytest.mark.parametrize("method", METHODS)
def test_hotel_frames_shuffled(method):
    frames = load_landmark_folder(HOTEL_SMALL)
    rng = np.random.default_rng(0)
    perms = [rng.permutation(fr.descriptors.shape[0]) for fr in frames]
    desc = [fr.descriptors[p] for fr, p in zip(frames, perms, strict=True)]
    edges = comm_graph("complete", [fr.name for fr in frames])
    links, _ = match_landmark_edges(desc, edges, kind=frames[0].descriptor_kind, ratio=None)
    truth = np.concatenate(perms)
    fpc = [len(p) for p in perms]
    labels = method(fpc, links)
    assert consistent(fpc, labels)
    same = (labels[:, None] == labels[None, :]) & (labels[:, None] >= 0)
    true = truth[:, None] == truth[None, :]
    cam = np.repeat(np.arange(len(fpc)), fpc)
    cross = cam[:, None] < cam[None, :]
    tp = (same & true & cross).sum()
    precision, recall = tp / (same & cross).sum(), tp / (true & cross).sum()
    kept = labels_to_kept(fpc, links, labels)
    good = truth[np.add(np.cumsum([0] + fpc[:-1])[links.cam_i], links.feat_i)] == \
        truth[np.add(np.cumsum([0] + fpc[:-1])[links.cam_j], links.feat_j)]
    assert precision > good.mean()                 # better than the links it was given
    assert precision >= 0.9 and recall >= 0.9
    assert good[kept].mean() >= 0.9


@pytest.mark.parametrize("rounding", ["sync", "clear"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rounding_does_not_depend_on_the_eigenbasis_or_its_last_bits(rounding, seed):
    """Another BLAS build (or the ARPACK path) returns another orthonormal basis of the same
    leading eigenspace, with other last bits: the rounding must name and assign the points
    alike. An exactly symmetric embedding (every row norm equal: 4 cameras x 3 points, each
    point's rows identical) leaves every pivot a tie, which used to go to rounding noise."""
    rng = np.random.default_rng(seed)
    k, n = 3, 4
    point = np.concatenate([rng.permutation(k) for _ in range(n)])  # each camera's features
    U = np.eye(k)[point] / np.sqrt(n)                           # rows of point p: e_p / 2
    camera = np.repeat(np.arange(n), k)
    Q, _ = np.linalg.qr(rng.standard_normal((k, k)))
    V = U @ Q + rng.normal(0.0, 1e-13, U.shape)
    if rounding == "sync":
        a = spectral._round_sync(U, camera, spectral.MAJORITY)
        b = spectral._round_sync(V, camera, spectral.MAJORITY)
    else:
        a, b = spectral._round_clear(U, camera), spectral._round_clear(V, camera)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    # each point's rows share a label, and the first row names point 0
    assert a[0][0] == 0 and all(np.unique(a[0][U[:, p] > 0]).size == 1 for p in range(k))


@pytest.mark.parametrize("kw", [dict(universe_size="2"), dict(universe_size=True),
                                dict(universe_size=2.5), dict(min_cosine=float("nan"))])
def test_loose_arguments_are_refused(kw):
    """'2', True and 2.5 were taken as 2, 1 and 2 landmarks; a nan cosine left every feature
    unassigned without a word."""
    links = Links([0, 0, 1], [0, 1, 0], [1, 1, 2], [0, 1, 0])
    with pytest.raises(ValueError, match="universe_size|min_cosine"):
        spectral_sync([2, 2, 1], links, **kw)


def test_labels_of_another_shape_are_refused():
    links = Links([0, 0], [0, 0], [1, 2], [0, 0])
    with pytest.raises(ValueError, match=r"labels of shape \(3, 1\): expected \(3,\)"):
        labels_to_kept([1, 1, 1], links, np.array([[4], [4], [-1]]))


@pytest.mark.parametrize("method", [*METHODS, spectral_sync_kept, clear_kept])
@pytest.mark.parametrize("links, needle", [
    (Links([0], [5], [1], [0]), r"link 0 \(0,5\)-\(1,0\): feature id out of range \(camera 0 "
                                r"has 2 features"),
    (Links([0], [0], [3], [1]), r"link 0 \(0,0\)-\(3,1\): camera id out of range 0\.\.1"),
])
def test_a_link_out_of_range_is_named_as_the_other_stages_name_it(method, links, needle):
    # a ValueError ('a link names a feature outside its camera's features') naming no link
    from pipeline.errors import InputError

    with pytest.raises(InputError, match=needle):
        method([2, 2], links)
