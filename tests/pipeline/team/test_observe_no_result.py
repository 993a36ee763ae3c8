"""Every robot's session ended and no result reached the observer (it was paused past the
robots' lease, or its links were cut): the observer stops with an error instead of writing a
run folder of no link that reports every robot crashed."""

import threading
import time

import pytest

from pipeline.errors import TeamError
from pipeline.team.launcher import make_team
from pipeline.team.observe import observe_team
from pipeline.transport.zenoh_transport import key, open_session


def test_robots_gone_without_a_result_reaching_the_observer_is_an_error():
    team = make_team("unheard-all", [[0, 1]], {"kind": "links", "links": "x.csv",
                                               "features_per_camera": [1, 1]}, n=2)

    def robot(i):  # runs, then ends; its result never reaches the observer
        s = open_session([team.endpoint(i)], [team.observer], f"robot {i}")
        token = s.liveliness().declare_token(key(team.name, "live", i))
        time.sleep(1.0)
        token.undeclare()
        s.close()

    threads = [threading.Thread(target=robot, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    try:
        t0 = time.monotonic()
        with pytest.raises(TeamError, match=r"^no robot's result reached this observer: every "
                                            r"robot's process ended without one reaching it "
                                            r"\(robots 0, 1\); .*run the team again$"):
            observe_team(team, timeout_s=60)
        assert time.monotonic() - t0 < 30
    finally:
        for t in threads:
            t.join()
