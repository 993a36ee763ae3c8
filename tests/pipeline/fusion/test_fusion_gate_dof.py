"""The vote of the fusion stage tests a 3-D landmark: its gate is the chi-square quantile with
3 degrees of freedom (eqs. 12–13 with ``d = 3``), in the exact mode as in the Metropolis one."""

import pytest
from scipy.stats import chi2

import pipeline.fusion.landmarks as landmarks
from pipeline.fusion.landmarks import fuse_tracks
from tests.pipeline.fusion.test_conflictive_track_not_fused import _rig


@pytest.mark.parametrize("gate,p", [("squared", 0.99), ("squared", 0.9), ("distance", 0.95)])
def test_exact_mode_gates_with_three_degrees_of_freedom(monkeypatch, gate, p):
    seen = []
    real = landmarks.exact_dynamic_voting

    def spy(*args, **kw):
        seen.append(kw["thr"])
        return real(*args, **kw)

    monkeypatch.setattr(landmarks, "exact_dynamic_voting", spy)
    views, feats, links, edges = _rig(second_feature_of_camera_0=False)
    fr = fuse_tracks(views, feats, links, edges, gate=gate, p=p)
    assert len(fr.points) == 1
    q = chi2.ppf(p, 3)
    assert seen == [pytest.approx(q * q if gate == "distance" else q, rel=1e-12)]
