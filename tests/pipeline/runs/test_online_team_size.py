"""An online run over zenoh counts the robot processes of a step's stage from the frames the
run can hold: a window longer than the run is no reason to refuse it
(pipeline.runs.transports.check_online_team_size)."""

import pytest

from pipeline.errors import InputError
from pipeline.runs.transports import check_online_team_size
from pipeline.runs.transports.zenoh import MAX_ROBOT_PROCESSES


def test_a_window_longer_than_the_run_counts_the_run_s_frames():
    # 3 robots, 2 steps: at most 6 frames in any step's window, whatever --window says
    check_online_team_size("zenoh", 3, 100000, None, 2)
    check_online_team_size("zenoh", 3, 2, 100000, 2)
    robots = MAX_ROBOT_PROCESSES // 2  # 2 steps: just within the cap
    check_online_team_size("zenoh", robots, 10, None, 2)


def test_a_window_that_fills_is_still_counted_whole():
    robots = MAX_ROBOT_PROCESSES // 4 + 1  # window 3 + hold 2 = 5 frames each, 5 steps
    with pytest.raises(InputError, match=f"{robots * 5} frames in a step's window"):
        check_online_team_size("zenoh", robots, 3, None, 5)
    check_online_team_size("sim", robots, 3, None, 5)  # no cap on the simulator
