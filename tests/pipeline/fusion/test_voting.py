import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.fusion.consensus import RandomGeometricTopology
from pipeline.fusion.voting import (
    chi2_ppf,
    distributed_ml,
    dynamic_voting,
    gate_threshold,
    static_voting,
)

RING10 = np.array([(k, (k + 1) % 10) for k in range(10)] + [(0, 5), (2, 7)])


def conditions_case():
    """10 robots, 7 inliers in a small cluster, 3 outliers far away; isotropic covariances.

    With ``Λ_i = s_i I`` every ML of a subset of inliers is a convex combination of inlier
    observations (Condition 2). With the squared gate at p = 0.99 (radius 3.03 in units of
    sqrt(s_i)), the inliers' spread of 0.5 (s_i >= 0.5) gives Condition 1, the outliers' distance
    of >= 30 gives Condition 3, and any non-negative combination of inliers stays in their hull,
    so the outliers' distance never vanishes there (Condition 4).
    """
    rng = np.random.default_rng(5)
    inl = np.array([1, 1, 0, 1, 1, 0, 1, 1, 0, 1], dtype=bool)
    x = np.empty((10, 2))
    x[inl] = rng.uniform(-0.25, 0.25, size=(7, 2)) + [3.0, 5.0]
    x[~inl] = [[40.0, 5.0], [3.0, -30.0], [-30.0, -30.0]]
    s = rng.uniform(0.5, 2.0, size=10)
    cov = s[:, None, None] * np.eye(2)
    return x, cov, inl


def ml_of(x, cov, mask):
    info = np.linalg.inv(cov[mask])
    return np.linalg.solve(info.sum(0), (info @ x[mask][..., None]).sum(0)[:, 0])


def check_conditions(x, cov, inl, thr):
    info = np.linalg.inv(cov)
    xi = x[inl]
    r = xi[:, None] - xi[None]
    assert (np.einsum("abi,aij,abj->ab", r, info[inl], r) <= thr).all()  # Condition 1
    far = x[~inl][:, None] - xi[None]
    lo = np.min(np.sqrt(np.einsum("abi,aij,abj->ab", far, info[~inl], far)))
    assert lo ** 2 > 4 * thr  # Condition 3, with margin for the whole hull


@pytest.mark.parametrize("switching", [False, True])
def test_dynamic_voting_reaches_ml_of_inliers_thm_4_1(switching):
    x, cov, inl = conditions_case()
    thr = gate_threshold(2, 0.99, "squared")
    check_conditions(x, cov, inl, thr)
    members = np.zeros((10, 3), dtype=bool)
    members[0, 0] = True       # V_h ⊆ V_in
    members[[3, 6], 1] = True  # V_h ⊆ V_in, c = 2
    members[2, 2] = True       # an outlier's hypothesis
    topo = RandomGeometricTopology(10, 1, radius=0.5, seed=1) if switching else RING10
    res = dynamic_voting(x, cov, topo, K=3, p=0.99, gate="squared", rounds=400,
                         members=members[None], history=True)
    target = ml_of(x, cov, inl)
    for h in (0, 1):
        # Prop. 4.1 / Thm. 4.1: θ_i → ML of V_in and v_i → |V_in| / N for every robot
        assert np.allclose(res.history["theta"][-1, 0, :, h], target, atol=1e-6)
        assert np.allclose(res.history["v"][-1, 0, :, h], 0.7, atol=1e-6)
        # eq. (20): the outliers never vote for it
        assert not res.history["yes"][:, 0, ~inl, h].any()
        # eq. (19): from some round on, all inliers vote for it
        assert res.history["yes"][-50:, 0][:, inl, h].all()
    assert (res.winner[0] != 2).all()
    assert np.array_equal(res.inlier[0], inl)
    assert np.allclose(res.theta[0], target, atol=1e-6)


def test_dynamic_voting_singular_p_votes_no():
    x, cov, inl = conditions_case()
    members = np.zeros((1, 10, 1), dtype=bool)
    members[0, 0, 0] = True
    res = dynamic_voting(x, cov, RING10, K=1, p=0.99, gate="squared", rounds=3,
                         members=members, history=True)
    # at t = 0 only the member has P != 0; everybody else's P is singular and votes no
    assert np.array_equal(res.history["yes"][0, 0, :, 0], members[0, :, 0])


def test_static_voting_reaches_ml_of_inliers():
    x, cov, inl = conditions_case()
    res = static_voting(x, cov, RING10, K=6, c=1, p=0.99, gate="squared",
                        rounds=(300, 300, 300), rng=0)
    assert res.members[0].any(0).all()
    assert np.array_equal(res.inlier[0], inl)
    assert np.allclose(res.theta[0], ml_of(x, cov, inl), atol=1e-6)
    assert np.allclose(res.votes[0].max(-1), 0.7, atol=1e-6)
    assert res.stats.rounds == 900


def test_distributed_ml_and_batch_equals_single():
    rng = np.random.default_rng(8)
    B, N = 4, 10
    x = rng.normal(size=(B, N, 2)) * 3
    cov = np.broadcast_to(np.eye(2), (B, N, 2, 2)) * rng.uniform(0.3, 2, (B, N, 1, 1))
    res = distributed_ml(x, cov, RING10, rounds=300)
    for b in range(B):
        assert np.allclose(res.theta[b], ml_of(x[b], cov[b], np.ones(N, bool)), atol=1e-8)
    # vectorized over problems: a batch gives what each problem gives alone
    batch = dynamic_voting(x, cov, RING10, K=3, rounds=50, rng=4)
    for b in range(B):
        one = dynamic_voting(x[b], cov[b], RING10, K=3, rounds=50, members=batch.members[b:b + 1])
        assert np.allclose(one.theta[0], batch.theta[b])
        assert np.array_equal(one.inlier[0], batch.inlier[b])


def test_message_counts_per_round():
    x, cov, _ = conditions_case()
    res = dynamic_voting(x, cov, RING10, K=3, rounds=10, rng=0)
    E = len(RING10)
    assert res.stats.messages == 10 * 2 * E
    # K bundles of P (3 reals), q (2), v (1) in float64 + a uint16 degree
    assert res.stats.bytes == 10 * 2 * E * (3 * 6 * 8 + 2)
    assert res.maxc_stats.rounds == 9


def test_gate_readings():
    assert gate_threshold(2, 0.95, "squared") == pytest.approx(5.991, abs=1e-3)
    assert gate_threshold(2, 0.95, "distance") == pytest.approx(5.991 ** 2, abs=1e-2)
    with pytest.raises(InputError, match="gate"):
        gate_threshold(2, 0.95, "mahalanobis")


def test_chi2_ppf_is_scipy_stats_bit_for_bit():
    from scipy.stats import chi2

    for d in (1, 2, 3, 4, 6, 10):
        for p in (1e-9, 0.01, 0.5, 0.9, 0.95, 0.99, 0.999, 1 - 1e-12):
            assert chi2_ppf(p, d) == float(chi2.ppf(p, d)), (p, d)


def test_bad_covariance_is_named():
    x, cov, _ = conditions_case()
    cov = cov.copy()
    cov[4] = np.diag([1.0, -1.0])
    with pytest.raises(InputError, match="robot 4"):
        dynamic_voting(x, cov, RING10, K=1, rounds=1, rng=0)
    with pytest.raises(InputError, match="cov must have shape"):
        distributed_ml(x, cov[:5], RING10)


@pytest.mark.parametrize("call, needle", [
    (lambda x, cov, E: dynamic_voting(x, cov, E, K=0, rng=0), r"K \(hypotheses\) must be a "
     r"whole number >= 1, got 0"),  # numpy's 'cannot reshape array of size 0' in max-c
    (lambda x, cov, E: static_voting(x, cov, E, K=1.5, rng=0), r"got 1\.5"),
    (lambda x, cov, E: dynamic_voting(x, cov, E, K=3, rounds=-1, rng=0),
     "rounds must be a whole number >= 0, got -1"),  # no round run: x came back as given
    (lambda x, cov, E: distributed_ml(x, cov, E, rounds=-1), "rounds must be a whole number"),
    (lambda x, cov, E: static_voting(x, cov, E, K=3, rounds=5, rng=0),
     r"rounds must be three counts \(hypotheses, vote averaging, final ML\), got 5"),
])
def test_counts_that_are_not_counts_are_named(call, needle):
    x = np.array([[0.0, 0], [0.1, 0], [0, 0.1], [5, 5]])
    cov = np.tile(np.eye(2) * 0.01, (4, 1, 1))
    with pytest.raises(InputError, match=needle):
        call(x, cov, [[0, 1], [1, 2], [2, 3]])
