"""What a robot of the online stage holds and sends for its retired frames
(pipeline.consistency.engines.online): its border links and retired entries count in its
state, the names of retiring pieces in the step's traffic."""

from pipeline.consistency.engines.online import Frame, OnlineAssociation
from pipeline.consistency.engines.online_detection import LABEL_BYTES
from pipeline.consistency.engines.online_history import RETIRED_ENTRY_BYTES
from pipeline.types import Links


def _retired_track():
    """Window 2, hold 0, one feature per frame. Step 0: frames 0 (robot 0) and 1 (robot 1)
    linked; step 1: frame 2 (robot 0) linked to frame 0; step 2 retires step 0: link 0-1
    is final, 0-2 becomes robot 0's border link into the piece {0, 1}."""
    oa = OnlineAssociation(window=2, resolution="paper", hold=0)
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [1], [0]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [2], [0]))
    rec = oa.add_step([Frame(0, 1), Frame(1, 1)], Links([], [], [], []))
    return oa, rec


def test_a_robot_holds_its_border_links_and_its_retired_entries():
    oa, _ = _retired_track()
    assert oa.border_links.tolist() == [1] and oa.window_links.tolist() == []
    assert sorted(oa.ret_robot.tolist()) == [0, 1]
    window = 2 * 16                      # two window frames of one feature each
    border = 16                          # robot 0's link 0-2 into the piece
    assert oa.robot_state_bytes().tolist() == [window + border + RETIRED_ENTRY_BYTES,
                                               window + RETIRED_ENTRY_BYTES]


def test_the_name_of_a_retired_piece_is_sent_over_each_new_border_link():
    """Step 2 has no new link: its traffic is the piece's name sent over the new border link,
    one message of one label."""
    _, rec = _retired_track()
    assert rec["retire_bytes"] == LABEL_BYTES
    assert rec["messages"] == 1 and rec["bytes"] == LABEL_BYTES
