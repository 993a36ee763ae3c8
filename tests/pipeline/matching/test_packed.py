"""Features in compact form: the receiver matches exactly what it would have matched."""

import numpy as np
import pytest

from pipeline.matching.features import extract
from pipeline.matching.packed import matching_descriptors, pack_features, unpack_features
from pipeline.matching.pairs import match_pair
from pipeline.transport import Message


@pytest.fixture(scope="module")
def two_views():
    import data_synth

    return [data_synth.render_robot(i, "d", 0, (320, 240), None, None)[0] for i in (0, 1)]


def _match(views, a, b):
    pm = match_pair(0, 1, a, b, views[0].K, views[1].K, True)
    return pm.pairs, pm.ratio, pm.epipolar_error


@pytest.mark.parametrize("method,rootsift", [("sift", False), ("sift", True), ("orb", False),
                                             ("akaze", False)])
def test_receiver_matches_exactly_what_it_would_have_matched(two_views, method, rootsift):
    from pipeline.types import Features

    raw = [extract(v, method, 500) for v in two_views]
    # the features as extracted with the option: what the simulator matches
    direct = [extract(v, method, 500, rootsift=rootsift) for v in two_views]
    mine = Features(raw[0].keypoints, matching_descriptors(raw[0].descriptors, rootsift),
                    raw[0].scales, method)
    packed = pack_features(raw[1].keypoints, raw[1].descriptors, rootsift)
    kp, desc = unpack_features(packed)
    assert np.array_equal(mine.descriptors, direct[0].descriptors)
    assert np.array_equal(kp, direct[1].keypoints) and np.array_equal(desc, direct[1].descriptors)
    assert desc.dtype == direct[1].descriptors.dtype
    theirs = Features(kp, desc, np.zeros(len(kp), np.float32), method)
    got, want = _match(two_views, mine, theirs), _match(two_views, *direct)
    assert len(want[0]) > 20  # the pair has matches to compare
    for g, w in zip(got, want, strict=True):
        assert np.array_equal(g, w)
    # SIFT travels as bytes: a quarter of the float32 descriptor; binary ones as they are
    full = Message(1, 0, "features", {"keypoints": raw[1].keypoints,
                                      "descriptors": direct[1].descriptors}).nbytes
    compact = Message(1, 0, "features", packed).nbytes
    assert packed["descriptors"].dtype == np.uint8
    if method == "sift":
        assert compact < 0.3 * full
    else:
        assert compact <= full + 2


def test_non_integral_float_descriptors_travel_unchanged():
    d = np.array([[0.5, 1.0], [2.0, 3.0]], np.float32)
    p = pack_features(np.zeros((2, 2), np.float32), d, rootsift=False)
    assert p["descriptors"].dtype == np.float32
    assert np.array_equal(unpack_features(p)[1], d)
    # out of the byte range: also unchanged
    d2 = np.array([[0.0, 256.0]], np.float32)
    assert np.array_equal(unpack_features(pack_features(np.zeros((1, 2)), d2, False))[1], d2)
    # no feature at all
    kp, desc = unpack_features(pack_features(np.zeros((0, 2)), np.zeros((0, 128), np.float32),
                                             True))
    assert kp.shape == (0, 2) and desc.shape == (0, 128) and desc.dtype == np.float32
