"""The sets of an online step solved at their roots: the rule's weights of several sets at
once, and the solution of a set gathered at its root equal to the rule's on its bundles."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from test_online_association import _bundles, posed_streams

from pipeline.consistency.engines.online import OnlineAssociation
from pipeline.consistency.evidence import set_weights


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=posed_streams(max_steps=1))
def test_the_weights_of_several_sets_at_once_are_the_rules(data):
    """set_weights on all the sets of a step equals the rule's set_problem on each set."""
    from pipeline.consistency.evidence import set_problem
    from pipeline.matching.link_evidence import ratio_llr

    window, hold, stream = data
    (frames, links), = stream
    oa = OnlineAssociation(window, hold=hold, weigh=False)
    oa.add_step(frames, links)
    a, b = oa._ends(np.arange(len(links)))
    local = ratio_llr(1.0 - links.quality)
    img = lambda ids: np.searchsorted(oa.offset, ids, side="right") - 1  # noqa: E731
    kp = lambda ids: np.array([np.float32(oa.keypoints[i][g - oa.offset[i]])  # noqa: E731
                               for g, i in zip(ids, img(ids), strict=True)], np.float64)
    P = lambda ids: np.stack([oa.projection[i] for i in img(ids)])  # noqa: E731
    got = set_weights(a, b, img(a), img(b), local, kp, P)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(oa.label)
    comp = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)),
                                directed=False)[1][a]
    for c in np.unique(comp).tolist():
        on = np.flatnonzero(comp == c)
        ra, rb, _, _, w, _, _ = set_problem(_bundles(oa, a[on], b[on], local[on]))
        order = np.lexsort((np.maximum(a[on], b[on]), np.minimum(a[on], b[on])))
        assert (ra == np.minimum(a[on], b[on])[order]).all()
        np.testing.assert_allclose(got[on][order], w, rtol=0, atol=1e-12)
