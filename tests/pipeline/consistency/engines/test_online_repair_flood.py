"""The record's estimate of the history repair's flood without overturning
(``overturn=False``, pipeline.consistency.engines.online_history): the set's robots flood
the step's new links only, not the set's older window links."""

from pipeline.consistency.engines.online import Frame, OnlineAssociation
from pipeline.consistency.engines.online_detection import LABEL_BYTES
from pipeline.consistency.engines.online_history import FLOOD_LINK_BYTES, RETIRED_ENTRY_BYTES
from pipeline.types import Links


def test_without_overturn_the_repair_floods_the_steps_new_links():
    """Window 2, hold 0, three robots. Step 0: two tracks between frames 0 and 1 (robots 0,
    1); step 1 extends them to frames 3 and 4 and links frame 5 (robot 2) to frame 3, an
    older link of the set; step 2 retires step 0 (two pieces sharing frames 0 and 1) and
    its three new links join both pieces in one set of three robots."""
    oa = OnlineAssociation(window=2, resolution="paper", hold=0, robots_check=False,
                           overturn=False)
    oa.add_step([Frame(0, 2), Frame(1, 2), Frame(2, 0)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    oa.add_step([Frame(0, 1), Frame(1, 1), Frame(2, 1)],
                Links([0, 1, 3], [0, 1, 0], [3, 4, 5], [0, 0, 0]))
    rec = oa.add_step([Frame(0, 1), Frame(1, 1), Frame(2, 0)],
                      Links([3, 4, 6], [0, 0, 0], [6, 6, 7], [0, 0, 0], [0.9, 0.5, 0.7]))
    assert rec["cut_history"] == 1 and len(oa.ret_piece) == 4
    assert oa.links.step_cut.tolist()[-3:] == [-1, 2, -1]   # the weakest new link
    robots = 3
    compare = robots * (4 * RETIRED_ENTRY_BYTES + 2 * LABEL_BYTES)
    assert rec["history_bytes"] == compare + robots * FLOOD_LINK_BYTES * 3
