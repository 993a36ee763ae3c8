"""Homography truth where the two directions disagree: a scaling homography maps an error of
e px in image 1 to e / 2 px in image 0, so "mutually within tol_px" and "one way within
tol_px" tell links apart; and keypoints that share one nearest neighbour."""

import numpy as np

from pipeline.evaluation.truth import homography_link_truth, homography_true_pairs, truth_doubt
from pipeline.types import Links

# image 1 is image 0 at twice the size (full-resolution pixels; no downscaling)
H1 = np.stack([np.eye(3), np.diag([2.0, 2.0, 1.0])])
SCALES = np.ones((2, 2))


def test_a_link_within_tolerance_one_way_only_is_spurious():
    kp0 = np.array([[10.0, 10.0], [30.0, 30.0], [50.0, 50.0]])
    # (10, 10) -> (20, 20): 3 px from (23, 20) in image 1, 1.5 px back in image 0
    # (30, 30) -> (60, 60): 1.8 px from (61.8, 60), 0.9 px back
    # (50, 50) -> (100, 100): exactly 2 px from (102, 100), 1 px back
    kp1 = np.array([[23.0, 20.0], [61.8, 60.0], [102.0, 100.0]])
    links = Links([0, 0, 0], [0, 1, 2], [1, 1, 1], [0, 1, 2])
    good = homography_link_truth([kp0, kp1], links, H1, SCALES, 2.0)
    assert good.tolist() == [False, True, True]
    assert homography_link_truth([kp0, kp1], links, H1, SCALES, 3.0).tolist() == [True] * 3


def test_true_pairs_need_the_tolerance_both_ways():
    kp0 = np.array([[10.0, 10.0], [30.0, 30.0]])
    kp1 = np.array([[23.0, 20.0], [61.8, 60.0]])
    # global ids: image 1 starts at 2; (10, 10)-(23, 20) is 3 px off in image 1
    assert homography_true_pairs([kp0, kp1], H1, SCALES, 2.0).tolist() == [[1, 3]]
    assert homography_true_pairs([kp0, kp1], H1, SCALES, 3.0).tolist() == [[0, 2], [1, 3]]


def test_two_keypoints_with_one_nearest_neighbour_make_one_true_pair():
    # both keypoints of image 0 map within 2 px of the one keypoint of image 1, whose nearest
    # neighbour back is the first: one true pair, not two
    kp0 = np.array([[10.0, 10.0], [10.0, 10.6]])
    kp1 = np.array([[20.0, 20.4]])          # 0.4 px from (20, 20), 0.8 px from (20, 21.2)
    assert homography_true_pairs([kp0, kp1], H1, SCALES, 2.0).tolist() == [[0, 2]]
    swapped = homography_true_pairs([kp1 / 2, kp0 * 2], H1, SCALES, 2.0)
    assert swapped.tolist() == [[0, 1]]     # both map back 0.2 px and 0.4 px from it


def test_doubt_below_five_percent_of_at_least_twenty_links():
    assert truth_doubt(np.array([True] * 2 + [False] * 18), 2.0) is None    # 10 %
    assert truth_doubt(np.array([True] + [False] * 19), 2.0) is None         # 5 %: not under
    assert truth_doubt(np.array([False] * 19), 2.0) is None                  # 19 links
    msg = truth_doubt(np.array([True] + [False] * 20), 2.0)                  # 1 of 21
    assert msg is not None and msg.startswith("only 1 of 21 links agree")


def _shift(dx):
    return np.array([[1.0, 0, dx], [0, 1.0, 0], [0, 0, 1.0]])


def test_links_of_camera_pairs_with_one_sum_are_judged_with_their_own_homography():
    # pairs (0, 3) and (1, 2) both add up to 3: each is judged by its own H_ij
    H = np.stack([_shift(0), _shift(10), _shift(25), _shift(45)])
    kp = [np.array([[0.0, 0.0]]), np.array([[10.0, 5.0]]), np.array([[25.0, 5.0]]),
          np.array([[45.0, 0.0]])]
    links = Links([0, 1], [0, 0], [3, 2], [0, 0])
    good = homography_link_truth(kp, links, H, np.ones((4, 2)), 2.0)
    assert good.tolist() == [True, True]
    # camera 2's keypoint 15 px off: only the (1, 2) link is spurious
    moved = [kp[0], kp[1], np.array([[40.0, 5.0]]), kp[3]]
    assert homography_link_truth(moved, links, H, np.ones((4, 2)), 2.0).tolist() == [True, False]
