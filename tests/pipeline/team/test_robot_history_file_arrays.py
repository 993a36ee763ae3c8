"""A damaged history file of an online step (``data.history``, read by each robot before its
history check) ended the robot in a traceback (ValueError, IndexError deep in the check) or
went on with arrays of the wrong shape; now each is an InputError naming the file and the
array (pipeline.team.robot.load_history_inputs, equip_history_file)."""

import numpy as np
import pytest

from pipeline.consistency.history import HistoryInputs
from pipeline.consistency.robot import Robot
from pipeline.errors import InputError
from pipeline.team.robot import equip_history_file, load_history_inputs

#: robot 0 of a two-robot team, one feature each, one link 0:0 - 1:0; its feature borders
#: retired piece 20 (link 20)
GOOD = HistoryInputs(0, 0, 5, np.array([1]), np.array([0]), np.array([7]), np.array([0.9]),
                     np.array([False]), np.array([0]), np.array([20]), np.array([20]),
                     np.array([0.8]), np.array([True]), np.array([20]), np.array([2]),
                     np.array([0]), np.array([2])).to_arrays()


def _robot():
    return Robot(0, [1, 1], [1], [0], [0])


def _file(tmp_path, **change):
    path = tmp_path / "h.npz"
    np.savez(path, **{**GOOD, **change})
    return path


def test_a_good_file_equips_the_robot(tmp_path):
    robot = _robot()
    equip_history_file(robot, _file(tmp_path), 0)
    assert robot.history.row_id.tolist() == [7]
    assert robot.history.inp.border_r.tolist() == [0]


@pytest.mark.parametrize(("change", "message"), [
    (dict(row_quality=np.array(["x"])), r"array 'row_quality' \(shape \(1,\), dtype <U1\) is "
                                        r"not a list of finite numbers"),
    (dict(border_quality=np.array([np.nan])), "array 'border_quality' .* finite numbers"),
    (dict(row_s=np.array([[0]])), r"array 'row_s' \(shape \(1, 1\), dtype int64\) is not a "
                                  r"list of whole numbers >= 0"),
    (dict(row_nbr=np.array([-1])), "array 'row_nbr' .* whole numbers >= 0"),
    (dict(row_id=np.array([-2])), r"array 'row_id' .* whole numbers >= -1 \(-1: a history"),
    (dict(row_id=np.array([1.5])), "array 'row_id' .* whole numbers >= -1"),
    (dict(border_id=np.array([2**64 - 1], np.uint64)), "array 'border_id' .* dtype uint64"),
    (dict(row_hist=np.array(["yes"])), "array 'row_hist' .* true/false values"),
    (dict(border_head=np.array([1])), "array 'border_head' .* true/false values"),
    (dict(row_id=np.array([7, 8])), "array 'row_id' has 2 entries, 'row_nbr' 1: the row "
                                    "arrays go together"),
    (dict(entry_lo=np.array([], np.int64)), "array 'entry_lo' has 0 entries, 'entry_piece' 1"),
    (dict(head=np.array([0.5, 0, 5])), r"head \[0.5, 0.0, 5.0\] \(float64\) is not three "
                                       "whole numbers"),
    (dict(head=np.array([0, 0])), r"head \[0, 0\] \(int64\) is not three"),
])
def test_a_damaged_array_is_named(tmp_path, change, message):
    path = _file(tmp_path, **change)
    with pytest.raises(InputError, match=rf"^robot 0: data.history\[0\] {path}: {message}") as e:
        equip_history_file(_robot(), path, 0)
    assert "\n" not in str(e.value)


def test_a_missing_array_is_named(tmp_path):
    arrays = dict(GOOD)
    del arrays["border_piece"]
    np.savez(tmp_path / "h.npz", **arrays)
    with pytest.raises(InputError, match="has no array 'border_piece'"):
        load_history_inputs(tmp_path / "h.npz", 0)


def test_a_plain_npy_file_is_refused(tmp_path):
    np.save(tmp_path / "h.npy", np.zeros(3))
    with pytest.raises(InputError, match=r"h.npy is not a history file .* not an archive"):
        load_history_inputs(tmp_path / "h.npy", 0)


@pytest.mark.parametrize(("change", "message"), [
    (dict(border_r=np.array([5])), "array 'border_r' names feature 5, robot 0 has 1 feature;"),
    (dict(row_nbr=np.array([0])), r"row 0 \(arrays 'row_nbr', 'row_s': neighbour 0, its "
                                  r"feature 0\) is no link of robot 0"),
    (dict(row_nbr=np.array([1, 1]), row_s=np.array([0, 0]), row_id=np.array([7, 7]),
          row_quality=np.array([0.9, 0.9]), row_hist=np.array([False, False])),
     r"arrays 'row_nbr', 'row_s' name 2 rows \(1 link of robot 0\), its link table holds "
     "1 link"),
])
def test_a_file_that_does_not_fit_the_robot_is_named(tmp_path, change, message):
    path = _file(tmp_path, **change)
    with pytest.raises(InputError, match=rf"^robot 0: data.history\[0\] {path}: {message}"):
        equip_history_file(_robot(), path, 0)
