"""What one online step accepts (pipeline.consistency.engines.online): a new link joins a
frame of the step to a frame of the matching window."""

import pytest

from pipeline.consistency.engines.online import Frame, OnlineAssociation
from pipeline.errors import InputError
from pipeline.types import Links


def test_a_link_between_two_earlier_frames_is_refused():
    """Both ends in step 0's frames, both still in the matching window of step 1: the link
    is not new to the step, it is refused and names itself."""
    oa = OnlineAssociation(window=2, resolution="paper")
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0], [0], [1], [0]))
    with pytest.raises(InputError, match=r"^new link 0 \(0,1\)-\(1,1\): a new link joins a "
                                         r"frame of this step"):
        oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0], [1], [1], [1]))
    assert len(oa.links.ci) == 1  # nothing of the refused link was kept
