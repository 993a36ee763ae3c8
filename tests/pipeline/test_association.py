import numpy as np
import pytest

from pipeline.association import AssociationGraph, check_links, count_conflicts
from pipeline.errors import InputError
from pipeline.types import Links


def fig1_graph():
    """Paper Fig. 1: robots A,B,C,D = 0,1,2,3; f1^A-f2^D, f1^A-f1^B, f1^B-f1^C, f1^C-f1^D."""
    links = Links(cam_i=[0, 0, 1, 2], feat_i=[0, 0, 0, 0], cam_j=[3, 1, 2, 3], feat_j=[1, 0, 0, 0])
    return AssociationGraph([1, 1, 1, 2], links)


def test_fig1_counts():
    c = count_conflicts(fig1_graph())
    assert c.association_sets == 1
    assert c.conflictive_sets == 1
    assert c.m_sum == 5
    assert c.conflictive_features == 5


def test_blocks_symmetric_and_identity():
    g = fig1_graph()
    assert (g.block(0, 3).toarray() == g.block(3, 0).toarray().T).all()
    assert (g.block(3, 3).toarray() == np.eye(2, dtype=bool)).all()
    assert g.block(0, 2).nnz == 0


def test_consistent_chain_has_no_conflict():
    links = Links(cam_i=[0, 1], feat_i=[0, 0], cam_j=[1, 2], feat_j=[0, 0])
    c = count_conflicts(AssociationGraph([2, 2, 2], links))
    assert (c.association_sets, c.conflictive_sets, c.m_sum) == (1, 0, 3)


@pytest.mark.parametrize(
    "row, message",
    [
        ((0, 0, 0, 1), "self-link"),
        ((1, 0, 0, 0), "cam_i must be < cam_j"),
        ((0, 5, 1, 0), "feature id out of range"),
        ((0, 0, 7, 0), "camera id out of range"),
    ],
)
def test_check_links_names_bad_row(row, message):
    links = Links(*[[v] for v in row])
    with pytest.raises(InputError, match=message):
        check_links(links, [2, 2])


def test_check_links_rejects_one_to_many():
    links = Links(cam_i=[0, 0], feat_i=[0, 0], cam_j=[1, 1], feat_j=[0, 1])
    with pytest.raises(InputError, match="one-to-one"):
        check_links(links, [2, 2])


def test_feature_counts_whose_sum_overflows_int64_are_refused():
    from pipeline.association import camera_offsets
    from pipeline.consistency import resolve_conflicts

    with pytest.raises(InputError, match=r"sums to 9,223,372,036,854,775,810 features, more "
                                         r"than an int64 holds"):
        camera_offsets([2**63 - 1, 1, 1, 1])
    links = Links(cam_i=[0, 1, 2, 0], feat_i=[0, 0, 0, 1], cam_j=[1, 2, 3, 3], feat_j=[0, 0, 0, 0])
    with pytest.raises(InputError, match="more than an int64 holds"):
        resolve_conflicts([2**63 - 1, 1, 1, 1], [[0, 1], [1, 2], [2, 3], [0, 3]], links)


@pytest.mark.parametrize("fpc, bad", [([1, 1, 1, 2.5], r"features_per_camera\[3\] = 2.5"),
                                      ([1, 1, 1, -2], r"must be >= 0, got \[1, 1, 1, -2\]")])
def test_counts_that_are_not_whole_numbers_are_refused_naming_them(fpc, bad):
    # an int64 cast truncated 2.5 to 2 and judged the graph of other counts silently
    links = Links(cam_i=[0, 0, 1, 2], feat_i=[0, 0, 0, 0], cam_j=[3, 1, 2, 3], feat_j=[1, 0, 0, 0])
    with pytest.raises(InputError, match=bad):
        AssociationGraph(fpc, links)
    with pytest.raises(InputError, match=bad):
        check_links(links, fpc)


@pytest.mark.parametrize("links", [([0], [0], [1], [0]), None])
def test_links_that_are_not_a_links_record_are_refused_naming_the_type(links):
    # is_conflict_free / AssociationGraph failed with an AttributeError on 'cam_i'
    from pipeline.consistency.centralized import is_conflict_free

    for check in (lambda: check_links(links, [1, 1]), lambda: AssociationGraph([1, 1], links),
                  lambda: is_conflict_free([1, 1], links)):
        with pytest.raises(InputError, match=f"links must be a pipeline.types.Links .*not "
                                             f"{type(links).__name__}"):
            check()


def test_a_single_number_for_the_counts_is_refused_naming_it():
    # 4 (the number of cameras) was read as one camera of 4 features: resolve_conflicts then
    # said 'camera id out of range 0..0' of the first link
    from pipeline.association import camera_offsets
    from pipeline.consistency import resolve_conflicts

    links = Links(cam_i=[0, 0, 1, 2], feat_i=[0, 0, 0, 0], cam_j=[3, 1, 2, 3], feat_j=[1, 0, 0, 0])
    needle = "features_per_camera 4: give one count per camera"
    for call in (lambda: camera_offsets(4), lambda: check_links(links, 4),
                 lambda: resolve_conflicts(4, None, links)):
        with pytest.raises(InputError, match=needle):
            call()
