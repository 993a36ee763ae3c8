"""The traffic of the robots' history check in an online step's record
(pipeline.consistency.engines.online_history): added to the step's once, and not at all when
the stage's transport already counted it with its own messages (``counted``)."""

import pytest

from pipeline.consistency.engines.online import Frame, OnlineAssociation, simulated_stage
from pipeline.consistency.engines.online_detection import LABEL_BYTES
from pipeline.types import Links


@pytest.mark.parametrize("counted", [False, True])
def test_the_robots_check_is_counted_once(counted):
    """Two retired pieces that share robot frames meet at step 2 (the set of
    test_online_record's history check): the robots' check runs and cuts one link."""
    seen = []

    def stage(*args, **kw):
        res = simulated_stage(*args, **kw)
        if "history" in res.stats:
            res.stats["history"]["counted"] = counted
        seen.append(res.stats)
        return res

    oa = OnlineAssociation(window=2, resolution="paper", hold=0, stage=stage)
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [0, 1], [2, 3], [0, 0]))
    rec = oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2, 3, 4], [0, 0, 0], [4, 4, 5],
                                                        [0, 0, 0], [0.9, 0.5, 0.7]))
    st = seen[-1]
    h = st["history"]
    assert rec["cut_history"] == 1 and h["bytes"] > 0 and h["messages"] > 0
    labels = 3 * 2 * LABEL_BYTES                       # the three new links' labels
    extra_bytes, extra_messages = (0, 0) if counted else (h["bytes"], h["messages"])
    assert rec["bytes"] == st["bytes"] + labels + rec["retire_bytes"] + extra_bytes
    assert rec["messages"] == st["messages"] + 3 + rec["retire_bytes"] // LABEL_BYTES \
        + extra_messages
    assert rec["history_bytes"] == h["bytes"]
    # its rounds follow the rule's, in the resolution phase
    assert rec["history_rounds"] == h["rounds"] > 0
    assert rec["resolution_rounds"] == st["resolution_rounds"] + h["rounds"]
    assert rec["rounds"] == st["detection_rounds"] + rec["resolution_rounds"]
