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
    """set_weights on all the sets of a step equals, on each set, the rule's weight computed
    from its bundles link by link: the local evidence plus TRIANGLE_WEIGHT times the support
    term of the triangles triangle_support counts there (every caller's weights, set_problem's
    included, are set_weights: this is the reference it is held to)."""
    from pipeline.consistency.cycles import shared_cameras, support_term
    from pipeline.consistency.evidence import (
        TRIANGLE_WEIGHT,
        node_cameras,
        set_geometry,
        set_links,
        triangle_support,
    )
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
        bundles = _bundles(oa, a[on], b[on], local[on])
        ra, rb, ca, cb, w0 = set_links(bundles)
        tau = triangle_support(ra, rb, node_cameras(ra, rb, ca, cb), *set_geometry(bundles))
        w = w0 + TRIANGLE_WEIGHT * support_term(tau, shared_cameras(ra, rb, ca, cb), False)
        order = np.lexsort((np.maximum(a[on], b[on]), np.minimum(a[on], b[on])))
        assert (ra == np.minimum(a[on], b[on])[order]).all()
        np.testing.assert_allclose(got[on][order], w, rtol=0, atol=1e-12)
