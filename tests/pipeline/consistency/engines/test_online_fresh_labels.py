"""Step 4 of an online step (pipeline.consistency.engines.online_history): every set the
stage ran on gets a name no earlier set had, so a later step touches only its own tracks."""

from pipeline.consistency.engines.online import Frame, OnlineAssociation
from pipeline.types import Links


def test_sets_of_two_steps_get_two_names_and_a_later_step_touches_one():
    """Window 3 (nothing retires). Step 0 links frames 0-1 (set A), step 1 frames 2-3 (set
    B), step 2 links frame 4 to frame 2: its sub-problem is B and the new feature only."""
    oa = OnlineAssociation(window=3, resolution="paper")
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [0], [1], [0]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2], [0], [3], [0]))
    a, b = oa.label[[0, 1]].tolist(), oa.label[[2, 3]].tolist()
    assert a[0] == a[1] and b[0] == b[1] and a[0] != b[0]
    rec = oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2], [0], [4], [0]))
    assert rec["touched_labels"] == 2 and rec["sub_features"] == 3
    assert oa.last_sub.tolist() == [2, 3, 4]
    assert oa.label[0] == a[0] and len(set(oa.label[[0, 2, 5]].tolist())) == 3
