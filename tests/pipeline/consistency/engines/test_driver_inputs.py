"""resolve_conflicts called from a user's code with inputs it must refuse, naming them."""

import numpy as np
import pytest

from pipeline.consistency import resolve_conflicts
from pipeline.errors import InputError
from pipeline.types import Links

FIG1 = dict(cam_i=[0, 1, 2, 0], feat_i=[0, 0, 0, 1], cam_j=[1, 2, 3, 3], feat_j=[0, 0, 0, 0])


@pytest.mark.parametrize("resolution", ["sync", "evidence"])
def test_a_nan_quality_or_weight_is_named(resolution):
    """sync ran out of Borůvka rounds on a NaN ('did not end within 5 Borůvka rounds'): its
    order of the links needs numbers."""
    links = Links(**FIG1, quality=[1.0, np.nan, 0.5, 0.2])
    with pytest.raises(InputError, match=r"link 1 \(1,0\)-\(2,0\) has quality nan"):
        resolve_conflicts([2, 1, 1, 1], None, links, resolution=resolution)
    with pytest.raises(InputError, match="has link_weight nan"):
        resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), resolution=resolution,
                          link_weight=[np.nan, 1, 1, 1])


@pytest.mark.parametrize("ids, needle", [
    ([0.4, 1.6], r"Links: feat_i\[0\] = .*0\.4 is not a whole-number id"),
    ([0, np.nan], r"feat_i\[1\] = .*nan"),
    ([0, 1e30], r"feat_i\[1\] = .*1e\+30"),
    (np.array([0, 2**63], dtype=np.uint64), r"feat_i\[1\] = .*9223372036854775808"),
])
def test_ids_that_are_not_whole_numbers_are_refused(ids, needle):
    """A cast to int64 truncated 1.6 to 1, wrapped 2**63 to a negative id."""
    with pytest.raises(ValueError, match=needle):
        Links([0, 0], ids, [1, 1], [0, 1])


def test_whole_number_floats_are_ids():
    links = Links([0.0, 1.0], [1.0, 0], [1, 2], [0, 0])
    assert links.cam_i.dtype == np.int64 and links.cam_i.tolist() == [0, 1]


def test_feature_counts_that_are_not_whole_numbers_are_named():
    with pytest.raises(InputError, match=r"features_per_camera\[0\] = .*2\.7"):
        resolve_conflicts([2.7, 1], None, Links([0], [1], [1], [0]))


def test_a_feature_count_too_large_to_hold_is_refused_before_any_allocation():
    """2**40 features on one camera allocated 8 TiB (MemoryError)."""
    with pytest.raises(InputError, match="sums to 1,099,511,627,780 features"):
        resolve_conflicts([2, 1, 1, 2**40], None, Links(**FIG1))


def test_votes_refuse_what_resolve_conflicts_refuses():
    """refine_by_votes took a link off the comm graph, a self-link or a negative id and
    returned links the input never had."""
    from pipeline.matching.votes import refine_by_votes

    with pytest.raises(InputError, match="not neighbours in the communication graph"):
        refine_by_votes([1, 1, 1, 1], [[0, 1], [0, 3], [1, 2], [2, 3]], Links([0], [0], [2], [0]))
    with pytest.raises(InputError):
        refine_by_votes([1, 1, 1], [[0, 1], [1, 2]], Links([1], [0], [1], [0]))
    with pytest.raises(InputError):
        refine_by_votes([3, 1], [[0, 1]], Links([0], [-1], [1], [0]))
    with pytest.raises(InputError, match="vote iterations 1.5"):
        refine_by_votes([1, 1], [[0, 1]], Links([0], [0], [1], [0]), iterations=1.5)
    refined, _ = refine_by_votes([1, 1], None, Links([0], [0], [1], [0]))  # None: as resolve
    assert len(refined) == 1


def test_evidence_inputs_of_the_wrong_size_are_named():
    """A keypoints list too short was an IndexError, a (3, 3) projection a reshape error."""
    kp = [np.zeros((2, 2)), np.zeros((1, 2)), np.zeros((1, 2))]
    with pytest.raises(InputError, match="keypoints has 3 entries for 4 cameras"):
        resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), resolution="evidence", keypoints=kp)
    kp.append(np.zeros((3, 2)))
    with pytest.raises(InputError, match=r"keypoints of camera 3 have shape \(3, 2\)"):
        resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), resolution="evidence", keypoints=kp)
    kp[3] = np.zeros((1, 2))
    P = [np.eye(3, 4)] * 3 + [np.eye(3)]
    with pytest.raises(InputError, match=r"projection of camera 3 has shape \(3, 3\)"):
        resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), resolution="evidence", keypoints=kp,
                          projections=P)


def test_detect_once_checks_the_links():
    from pipeline.consistency.engines.driver import detect_once

    with pytest.raises(InputError):
        detect_once([2, 1, 1, 1], Links([0], [0], [0], [1]))  # a self-link, read as a conflict


def test_detect_once_refuses_feature_counts_as_resolve_conflicts_does():
    """detect_once had no cap: 2**40 features on one camera tried to allocate 8 TiB."""
    from pipeline.consistency.engines.driver import detect_once

    with pytest.raises(InputError, match="sums to 1,099,511,627,780 features"):
        detect_once([2, 1, 1, 2**40], Links(**FIG1))


@pytest.mark.parametrize("links", [None, ([0, 1, 2, 0], [0, 0, 0, 1], [1, 2, 3, 3], [0, 0, 0, 0]),
                                   FIG1])
def test_links_that_are_not_a_links_are_named(links):
    """A tuple of columns raised AttributeError ('tuple' object has no attribute 'cam_i'),
    None a TypeError, inside the check."""
    from pipeline.consistency.engines.driver import detect_once

    for call in (lambda: resolve_conflicts([2, 1, 1, 1], None, links),
                 lambda: detect_once([2, 1, 1, 1], links)):
        with pytest.raises(InputError, match=rf"links must be a pipeline.types.Links .*not "
                                             rf"{type(links).__name__}"):
            call()


@pytest.mark.parametrize("weight, needle", [
    (["a", "b", "c", "d"], r"link_weight must be numbers, one per link \(could not convert "
                           r"string to float: 'a'\)"),  # a bare ValueError of numpy's
    ([[1, 2], [3, 4]], r"link_weight must be a flat sequence .*shape \(2, 2\)"),  # flattened
])
def test_link_weight_that_is_not_one_number_per_link_is_named(weight, needle):
    with pytest.raises(InputError, match=needle):
        resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), link_weight=weight)


@pytest.mark.parametrize("kw, needle", [
    (dict(network_options={"drop_probability": 0.1}), "network_options must be a "
     "pipeline.transport.simulated.NetworkOptions or None, not dict"),
    (dict(protocol={"reliable": True}), "protocol must be a "
     "pipeline.consistency.protocols.ProtocolOptions or None, not dict"),
])
def test_options_given_as_a_dict_are_named(kw, needle):
    # an AttributeError ('dict' object has no attribute 'seed') from inside the network
    from pipeline.consistency import detect_once

    with pytest.raises(InputError, match=needle):
        resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), **kw)
    with pytest.raises(InputError, match=needle):
        detect_once([2, 1, 1, 1], Links(**FIG1), **kw)


@pytest.mark.parametrize("camera, value, what", [(0, np.nan, "keypoints"),
                                                 (1, np.inf, "projection")])
def test_a_non_finite_keypoint_or_projection_is_named(camera, value, what, monkeypatch):
    # the evidence rule's geometric test: numpy's 'SVD did not converge' on a NaN keypoint,
    # and an SVD that never returned on an inf in a projection (refused before it runs)
    from pipeline.consistency import evidence

    def never(*args, **kwargs):
        raise AssertionError("the geometric test ran on a non-finite input")

    monkeypatch.setattr(evidence, "_consistent", never)
    m = [2, 1, 1, 1]
    kp = [np.zeros((k, 2)) for k in m]
    P = [np.hstack([np.eye(3), [[i], [0], [0]]]) for i in range(4)]
    (kp if what == "keypoints" else P)[camera][0, 0] = value
    with pytest.raises(InputError, match=rf"{what} of camera {camera}: a non-finite value at "
                                         rf"\(0, 0\) \({value}\)"):
        resolve_conflicts(m, None, Links(**FIG1), keypoints=kp, projections=P)


def test_the_simulator_hands_both_ends_of_a_link_its_one_value():
    """A robot process reads its own rows and the two ends compare them
    (pipeline.team.robot.check_shared_links); the simulator takes one row per link and hands
    both ends that row's value, so the ends cannot disagree: a link given twice (either way
    round, with two qualities) is refused, and each end's weight is its link's."""
    from pipeline.consistency.engines.driver import _equip_evidence, build_robots
    from pipeline.consistency.sync import equip_robot

    for cam_i, cam_j in (([0, 0], [1, 1]), ([0, 1], [1, 0])):
        with pytest.raises(InputError, match="duplicate link|cam_i must be < cam_j"):
            resolve_conflicts([1, 1], None, Links(cam_i, [0, 0], cam_j, [0, 0], [0.9, 0.8]),
                              resolution="sync")
    links = Links(**FIG1)
    w = np.array([0.5, -1.0, 2.0, np.inf])
    robots, index = build_robots([2, 1, 1, 1], links)
    _equip_evidence(robots, index, links, w, None, None, equip_robot)
    seen: dict = {}
    for rb, li in zip(robots, index, strict=True):
        for k, link in enumerate(li.tolist()):
            seen.setdefault(link, []).append(rb.sync.weight[k])
    assert seen == {k: [w[k], w[k]] for k in range(len(w))}


@pytest.mark.parametrize("resolution", ["evidence", "sync", "paper-labels"])
def test_the_papers_protocol_on_a_faulty_network_is_refused_for_a_rule_that_needs_none(
        resolution):
    """ProtocolOptions(reliable=False) with drops failed with a KeyError inside the evidence
    rule, or a StageStalledError of sync's or the label flooding's rounds; 'paper' keeps
    running as is (the faults bench measures how it breaks)."""
    from pipeline.consistency import ProtocolOptions
    from pipeline.transport.simulated import NetworkOptions

    lossy = NetworkOptions(drop_probability=0.3, seed=2)
    with pytest.raises(InputError, match=rf"ProtocolOptions\(reliable=False\) on a faulty "
                                         rf"network: rule '{resolution}' needs a lossless"):
        resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), lossy,
                          protocol=ProtocolOptions(reliable=False), resolution=resolution)
    res = resolve_conflicts([2, 1, 1, 1], None, Links(**FIG1), lossy,
                            protocol=ProtocolOptions(reliable=False), resolution="paper")
    assert res.stats["protocol"] == "paper"


@pytest.mark.parametrize("edges", [None, np.array([[0, 1], [1, 2], [2, 3], [0, 3]])])
def test_detect_once_with_resolve_conflicts_argument_order_says_so(edges):
    """detect_once(m, comm_edges, links) was refused as 'links must be a pipeline.types.Links
    ..., not NoneType' (or ndarray), without a word of the swapped order."""
    from pipeline.consistency import detect_once

    with pytest.raises(InputError, match=r"detect_once takes \(features_per_camera, links, "
                                         r"comm_edges\): the links come second"):
        detect_once([2, 1, 1, 1], edges, Links(**FIG1))
    assert detect_once([2, 1, 1, 1], Links(**FIG1), edges).stats["conflictive_features"] == 5
