"""A robot whose process was killed after its start handshake and started again with the same
id: its neighbour writes the first process off and tells the new one so, instead of taking
it into rounds it never ran (pipeline.transport.zenoh_transport, "A neighbour started
again")."""

import threading

from pipeline.team.launcher import make_team
from pipeline.transport.zenoh_transport import ZenohTransport


def _open(team, i, lines, started):
    robot = ZenohTransport(team, i, round_timeout_s=30.0, log=lines.append)
    started[i] = robot
    robot.handshake(timeout_s=10.0)


def test_a_neighbour_started_again_is_written_off_and_told():
    team = make_team("restart", [[0, 1]], {"kind": "links", "links": "in.csv",
                                           "features_per_camera": [1, 1]}, n=2)
    lines0, lines1 = [], []
    robots = {}
    threads = [threading.Thread(target=_open, args=(team, i, ln, robots))
               for i, ln in ((0, lines0), (1, lines1))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    first = robots[1]
    again = None
    try:
        assert robots[0].written_off == {} and first.written_off == {}
        first.close()  # robot 1's process ends (killed) while robot 0 computes
        again = ZenohTransport(team, 1, round_timeout_s=30.0, log=lines1.append)
        again.handshake(timeout_s=10.0)
        assert robots[0].written_off == {1: "closed"}
        assert again.written_off == {0: "told"}
        assert any("robot 1 was started again" in line for line in lines0), lines0
    finally:
        robots[0].close()
        if again is not None:
            again.close()
