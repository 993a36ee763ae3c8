"""The history check's pieces a robot computes alone (pipeline.consistency.history)."""

import numpy as np
import pytest

from pipeline.consistency.history import HistoryInputs, rebuild, rebuild_halves


def _q(x: float) -> int:
    return int(np.float64(x).view(np.int64))


def test_rebuild_skips_the_link_that_would_hold_one_frame_twice():
    """Features 1 and 3 are frames of robot 0 at step 5; the stronger link 10 joins 1 and 2
    first, then 11 would bring 3 into the group: skipped."""
    groups = {1: {0: [(5, 5)]}, 2: {1: [(5, 5)]}, 3: {0: [(5, 5)]}}
    out = rebuild(groups, np.array([10, 11]), np.array([1, 2]), np.array([2, 3]),
                  np.array([0.9, 0.5]))
    assert out.tolist() == [11]


def test_rebuild_keeps_retired_pieces_apart_when_their_runs_overlap():
    """Two pieces (nodes -1, -2) both hold robot 4's frames of steps 0-2 and 2-3: the weaker
    of the two border links that would join them through window feature 7 is skipped."""
    groups = {7: {0: [(9, 9)]}, -1: {4: [(0, 2)]}, -2: {4: [(2, 3)]}}
    out = rebuild(groups, np.array([3, 4]), np.array([7, 7]), np.array([-1, -2]),
                  np.array([0.4, 0.6]))
    assert out.tolist() == [3]


def test_rebuild_halves_joins_the_two_halves_of_a_link_and_skips_a_lone_half():
    """Link 20 arrives from both its robots (features 1 and 2), link 21 from one only (a lost
    message): 21 is skipped, 20 kept; border link 30 joins feature 2 to piece 5."""
    halves = [(20, 1, 0, 5, _q(0.9), -1), (20, 2, 1, 5, _q(0.9), -1),
              (21, 2, 1, 5, _q(0.8), -1), (30, 2, 1, 5, _q(0.3), 5)]
    assert rebuild_halves(halves, [(5, 2, 0, 1)]).tolist() == [21]


def test_rebuild_halves_decides_as_rebuild_on_the_same_links():
    """Three features of robots 0, 1, 0 (steps 5, 5, 5): the same skip as rebuild."""
    halves = [(10, 1, 0, 5, _q(0.9), -1), (10, 2, 1, 5, _q(0.9), -1),
              (11, 2, 1, 5, _q(0.5), -1), (11, 3, 0, 5, _q(0.5), -1)]
    assert rebuild_halves(halves, []).tolist() == [11]


def test_inputs_go_through_named_arrays_unchanged():
    inp = HistoryInputs(40, 3, 7, np.array([1, 2]), np.array([0, 1]), np.array([5, -1]),
                        np.array([0.5, 1.0]), np.array([False, True]), np.array([1]),
                        np.array([9]), np.array([12]), np.array([0.25]), np.array([True]),
                        np.array([9, 9]),
                        np.array([0, 3]), np.array([1, 2]), np.array([1, 4]))
    back = HistoryInputs.from_arrays(inp.to_arrays())
    assert (back.gid0, back.robot, back.step) == (40, 3, 7)
    for k in HistoryInputs.ARRAYS:
        np.testing.assert_array_equal(getattr(back, k), getattr(inp, k))


@pytest.mark.parametrize("base", [5, 2**40])
def test_two_frames_joining_two_overlapping_pieces_cut_the_weaker_border_link(base):
    """Two frames linked (link 7, quality 0.9), each bordering its own retired piece (links 20
    and 21); robot 2's frames of step 2 are in both pieces: the robots name the set, echo the
    entries to its root, and the weakest link that closes the clash (21) is cut by the robot
    holding it. Piece names beyond an int32 travel as int64, with the same decision."""
    from pipeline.consistency.engines.history_run import run_history
    from pipeline.types import Links

    P, Q = base, base + 1

    def frame(gid0, robot, piece, bid, q):
        return HistoryInputs(gid0, robot, 5, np.array([1 - robot]), np.array([0]),
                             np.array([7]), np.array([0.9]), np.array([False]), np.array([0]),
                             np.array([piece]), np.array([bid]), np.array([q]),
                             np.array([True]), np.array([piece]), np.array([2]),
                             np.array([0 if piece == P else 2]),
                             np.array([2 if piece == P else 3]))

    out = run_history([1, 1], Links([0], [0], [1], [0], [0.9]), np.array([True]),
                      [frame(0, 0, P, 20, 0.8), frame(10, 1, Q, 21, 0.3)])
    assert out["cut"].tolist() == [21]
    assert out["phases"]["names"] > 0 and out["phases"]["repair"] > 0
