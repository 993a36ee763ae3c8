"""A robot of a team of photographs that never published (its process killed, a hand-started
robot stopped): ``run-images --transport zenoh`` and ``observe`` said only "robot 1 (b.jpg)
did not publish a result"; the line now says why a run of photographs stops there, that
nothing was written, and what to do."""

from types import SimpleNamespace

import pytest

from pipeline.errors import TeamError
from pipeline.runs.transports.zenoh import images_of_run


def test_a_photograph_robot_that_never_published_is_one_line_saying_what_to_do():
    views = [SimpleNamespace(name="a.jpg"), SimpleNamespace(name="b.jpg"),
             SimpleNamespace(name="c.jpg")]
    run = SimpleNamespace(results={0: None, 2: None}, killed=set())
    with pytest.raises(TeamError) as exc:
        images_of_run(None, views, SimpleNamespace(n=3), run)
    msg = str(exc.value)
    assert msg.startswith("robot 1 (b.jpg) did not publish a result: ")
    assert "nothing was written: run the team again" in msg
    assert "\n" not in msg
