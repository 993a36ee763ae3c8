"""Per-link evidence: the log-likelihood ratios by hand, the known-pose geometry, the checks."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.errors import InputError
from pipeline.matching.link_evidence import (
    MIN_SCALE_PX,
    RATIO_EPS,
    RATIO_TIE_SLOPE,
    LinkEvidence,
    edge_evidence,
    geometric_llr,
    link_evidence,
    pose_fundamental,
    ratio_llr,
)
from pipeline.types import Features, Links, PairMatches, View


def test_ratio_llr_by_hand():
    np.testing.assert_allclose(ratio_llr([0.5, 0.2, 0.8]), [0.0, np.log(4), -np.log(4)])
    assert np.isfinite(ratio_llr([0.0, 1.0])).all()  # clipped


@given(st.lists(st.integers(0, 5_000_000), min_size=2, max_size=30, unique=True))
def test_ratio_llr_keeps_the_order_of_the_ratios_beyond_the_clip(micro):
    """An assignment may pair a feature with another than its nearest neighbour (ratio > 1):
    the log-odds still order those links by their ratio (the greedy merge reads the order).
    Ratios on a grid of 1e-6 (closer ones may round to one float of log-odds)."""
    r = np.sort(np.asarray(micro)) / 1e6
    llr = ratio_llr(r)
    assert np.isfinite(llr).all() and (np.diff(llr) < 0).all()
    inside = (r >= RATIO_EPS) & (r <= 1 - RATIO_EPS)
    np.testing.assert_allclose(llr[inside], np.log((1 - r[inside]) / r[inside]))
    outside = ~inside  # within RATIO_TIE_SLOPE per unit of ratio of the clipped value
    clipped = np.clip(r[outside], RATIO_EPS, 1 - RATIO_EPS)
    np.testing.assert_allclose(llr[outside], np.log((1 - clipped) / clipped)
                               - RATIO_TIE_SLOPE * (r[outside] - clipped))


def test_geometric_llr_by_hand():
    # one edge, errors with median ln 2 → scale β = 1; T = 2 px: llr = log(2) − e
    e = np.array([0.0, np.log(2.0), 3.0])
    np.testing.assert_allclose(geometric_llr(e, np.zeros(3), 2.0), np.log(2.0) - e)
    # the scale is per edge and floored; nan carries no evidence
    out = geometric_llr(np.array([0.0, 0.0, np.nan]), np.array([0, 0, 1]), 1.0)
    np.testing.assert_allclose(out, [np.log(1.0 / MIN_SCALE_PX)] * 2 + [0.0])


def test_pose_fundamental_holds_for_a_projected_point():
    rng = np.random.default_rng(0)
    K = np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    Ri, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Rj, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    ti, tj = rng.normal(size=3), rng.normal(size=3)
    X = Ri.T @ (np.array([0.3, -0.2, 6.0]) - ti)  # in front of camera i
    xi = K @ (Ri @ X + ti)
    xj = K @ (Rj @ X + tj)
    F = pose_fundamental(K, Ri, ti, K, Rj, tj)
    assert abs((xj / xj[2]) @ F @ (xi / xi[2])) < 1e-9 * np.linalg.norm(F)


def _scene():
    K = np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    views = [View("a", np.zeros((4, 4)), K, np.eye(3), np.zeros(3)),
             View("b", np.zeros((4, 4)), K, np.eye(3), np.array([-1.0, 0, 0]))]
    X = np.array([[0.0, 0, 5], [0.5, 0.2, 6], [-0.4, 0.1, 4]])
    kp = [(X @ K.T)[:, :2] / X[:, 2:], ((X + [-1.0, 0, 0]) @ K.T)[:, :2] / X[:, 2:]]
    kp[1][2] += [0.0, 5.0]  # feature 2 of b is off its epipolar line by 5 px
    feats = [Features(k.astype(np.float32), np.zeros((3, 8), np.float32), np.ones(3, np.float32),
                      "sift") for k in kp]
    pm = PairMatches(0, 1, np.array([[0, 0], [1, 1], [2, 2]], np.int32),
                     np.array([0.3, 0.3, 0.3], np.float32), np.array([0.1, 0.1, 0.1], np.float32))
    return views, feats, pm


def test_link_evidence_uses_known_poses():
    views, feats, pm = _scene()
    links = Links.from_matches([pm])
    ev = link_evidence([pm], links, views, feats)
    assert ev.pose_error[:2].max() < 1e-3 and ev.pose_error[2] > 2.0
    assert ev.weight[2] < ev.weight[0] and ev.weight[0] == ev.weight[1]
    # without poses: the RANSAC Sampson errors (all equal here) and the ratio only
    no_pose = link_evidence([pm], links)
    assert np.isnan(no_pose.pose_error).all() and np.ptp(no_pose.weight) == 0
    assert len(ev.subset(np.array([True, False, True])).weight) == 2


def test_link_evidence_rejects_links_that_are_not_the_matches():
    _, _, pm = _scene()
    with pytest.raises(InputError, match="Links.from_matches"):
        link_evidence([pm], Links([0], [0], [1], [0]))


def test_from_quality_reads_one_minus_ratio():
    ev = LinkEvidence.from_quality(Links([0, 0], [0, 1], [1, 1], [0, 1], [0.5, 0.8]))
    np.testing.assert_allclose(ev.ratio, [0.5, 0.2])
    np.testing.assert_allclose(ev.weight, ratio_llr([0.5, 0.2]))


def test_edge_evidence_equals_link_evidence_edge_by_edge():
    """What two robots compute for their edge is the centralized evidence of its links."""
    views, feats, pm = _scene()
    rng = np.random.default_rng(2)
    # a second edge with other errors: the scale is per edge in both forms
    pm2 = PairMatches(0, 1, np.array([[0, 1], [2, 0]], np.int32),
                      rng.uniform(0.2, 0.8, 2).astype(np.float32),
                      rng.uniform(0.0, 1.0, 2).astype(np.float32))
    pm.epipolar_error = rng.uniform(0.0, 1.0, 3).astype(np.float32)
    links = Links.from_matches([pm, pm2])
    for v, f in ((views, feats), (None, None)):
        whole = link_evidence([pm, pm2], links, v, f)
        poses = [None, None] if v is None else [(x.K, x.R, x.t) for x in v]
        parts = [edge_evidence(m, feats[0].keypoints, feats[1].keypoints, *poses)
                 for m in (pm, pm2)]
        assert np.concatenate([p.weight for p in parts]).tobytes() == whole.weight.tobytes()
