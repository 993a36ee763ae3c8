"""Every robot lost is named, not the first alone: with two photo robots that never
published, or two robot processes lost in a consistency stage, the one-line message named one
and the user fixed that robot only to meet the next."""

from types import SimpleNamespace

import pytest

from pipeline.errors import TeamError, listed, processes_lost
from pipeline.runs.transports.zenoh import images_of_run


def test_listed_names_every_item_up_to_its_limit_then_counts():
    assert listed([]) == ""
    assert listed([3]) == "3"
    assert listed([3, 7]) == "3 and 7"
    assert listed([3, 7, 9]) == "3, 7 and 9"
    assert listed(range(8)) == "0, 1, 2, 3, 4 and 3 more"
    assert listed(range(8), limit=8) == "0, 1, 2, 3, 4, 5, 6 and 7"
    assert listed([3, 7, 9], last=", ") == "3, 7, 9"
    assert listed(range(8), last=", ") == "0, 1, 2, 3, 4 and 3 more"


def test_processes_lost_is_singular_for_one_and_names_all_of_several():
    assert processes_lost(["'a.jpg'"]) == "the robot process of image 'a.jpg' was lost"
    assert processes_lost([2, 5]) == "the robot processes of images 2 and 5 were lost"


def test_two_photo_robots_that_never_published_are_both_named():
    views = [SimpleNamespace(name=f"{c}.jpg") for c in "abcd"]
    run = SimpleNamespace(results={0: None, 2: None}, killed=set())
    with pytest.raises(TeamError) as exc:
        images_of_run(None, views, SimpleNamespace(n=4), run)
    msg = str(exc.value)
    assert msg.startswith("robots 1 (b.jpg) and 3 (d.jpg) did not publish a result: each "
                          "one's process ended")
    assert "\n" not in msg
