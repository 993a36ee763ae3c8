"""A robot's own detection (Sec. III): which features get a row, rules (8)-(9) on the rows,
and the root of eq. (10), on rows set by hand."""

import numpy as np
import scipy.sparse as sp

from pipeline.consistency.detection import (
    find_conflictive_sets,
    init_detection,
    send_blocks,
    start_detection,
)
from pipeline.consistency.robot import Robot


def with_rows(robot: Robot, rows: list[list[int]]) -> Robot:
    """``robot.X`` holding ``rows`` (global ids) for its features, every feature active."""
    indptr = np.r_[0, np.cumsum([len(r) for r in rows])]
    indices = np.concatenate([np.sort(r) for r in rows]).astype(np.int64)
    robot.X = sp.csr_matrix((np.ones(indices.size, dtype=bool), indices, indptr),
                            shape=(robot.m, robot.m_total))
    robot.active = np.ones(robot.m, dtype=bool)
    return robot


def test_a_feature_without_a_link_gets_no_row():
    # robot 0: features 0 and 1 linked to robot 1, feature 2 linked to no one
    rb = Robot(0, [3, 2], [1, 1], [0, 1], [0, 1])
    rows = init_detection(rb, 1)
    assert rows.tolist() == [0, 1]
    assert rb.active.tolist() == [True, True, False]
    assert rb.X.nnz == 2 and rb.X[2].nnz == 0


def test_a_robot_whose_links_are_all_cut_stops_at_once_and_sends_nothing():
    rb = Robot(0, [2, 2], [1, 1], [0, 1], [0, 1])
    rb.link_alive[:] = False
    sent = []
    start_detection(rb, 2, lambda dst, kind, p: sent.append((dst, kind)))
    assert rb.stopped and sent == [] and not rb.active.any()


def test_rows_of_two_features_are_judged_apart():
    # cameras 0, 1, 2 with 1, 2, 1 features; robot 1's feature 0 is linked to camera 0, its
    # feature 1 to camera 2: the rows {0, 1} and {2, 3} hold each camera once. Read one after
    # the other, the last camera of the first row is the first of the second: still no conflict.
    rb = with_rows(Robot(1, [1, 2, 1], [0, 2], [0, 1], [0, 0]), [[0, 1], [2, 3]])
    find_conflictive_sets(rb)
    assert rb.conflictive.tolist() == [False, False]
    assert rb.set_label.tolist() == [-1, -1]
    assert rb.root_of_set == {}
    assert rb.track_label.tolist() == [0, 2]  # each set named by its smallest global id


def test_root_of_eq10_most_features_then_lowest_robot():
    # cameras 0, 1, 2 with 2, 2, 4 features (global ids 0-1, 2-3, 4-7)
    # set A = {0, 1, 2, 4, 5}: cameras 0 and 2 hold two features each -> root 0 (lowest id)
    # set B = {3, 6, 7}: camera 2 holds two, camera 1 one -> root 2 (most features)
    rb = with_rows(Robot(1, [2, 2, 4], [0, 2], [0, 1], [0, 2]), [[0, 1, 2, 4, 5], [3, 6, 7]])
    find_conflictive_sets(rb)
    assert rb.conflictive.tolist() == [True, True]
    assert rb.set_label.tolist() == [0, 3]
    assert rb.root_of_set == {0: 0, 3: 2}


def test_delta_messages_go_only_where_a_row_grew():
    # robot 0's features 0 and 1 are linked to robot 1, feature 2 to robot 2; only row 2 got a
    # new entry in the last step: robot 2 gets that row, robot 1 no message at all
    rb = Robot(0, [3, 2, 1], [1, 1, 2], [0, 1, 2], [0, 1, 0])
    init_detection(rb, 1)
    rb.X_new = sp.csr_matrix((np.ones(1, dtype=bool), ([2], [5])), shape=(rb.m, rb.m_total))
    sent = []
    send_blocks(rb, lambda dst, kind, p: sent.append((dst, kind, p["rows"].tolist())))
    assert sent == [(2, "blocks", [2])]
