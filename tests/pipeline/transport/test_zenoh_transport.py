"""The Zenoh transport's round clock: a round packet lost on the way is asked for again and
sent again, so the round completes (pipeline.transport.zenoh_transport, "A round packet
lost")."""

import threading

import numpy as np

from pipeline.team.launcher import make_team
from pipeline.transport.wire import decode_packet
from pipeline.transport.zenoh_transport import ZenohTransport


def test_a_lost_round_packet_is_asked_for_and_sent_again():
    team = make_team("again", [[0, 1]], {"kind": "links", "links": "in.csv",
                                         "features_per_camera": [1, 1]}, n=2)
    robots = [None, None]
    errors = []

    def open_robot(i):
        try:
            robots[i] = ZenohTransport(team, i, round_timeout_s=30.0, log=lambda s: None)
            robots[i].handshake(timeout_s=30.0)
        except Exception as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=open_robot, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    a, b = robots
    try:
        # robot 1's first put of its round-2 packet never reaches the wire
        put, lost = b._pubs[0].put, []

        def lossy_put(data):
            # the packet's own round, not ``b.round``: the sender thread puts a packet after
            # end_round queued it, when the robot's round counter may have moved on
            if not lost and decode_packet(data)[0]["round"] == 2:
                lost.append(data)
                return None
            return put(data)

        b._pubs[0] = type("Pub", (), {"put": staticmethod(lossy_put)})()
        got = [[], []]

        def run(i):
            rb = robots[i]
            for r in range(4):
                rb.send(1 - i, "x", {"r": np.array([r, i])})
                inbox, _ = rb.end_round()
                got[i].append([int(m.payload["r"][0]) for m in inbox])

        threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        assert lost, "the test did not lose a packet"
        assert got == [[[0], [1], [2], [3]], [[0], [1], [2], [3]]]
        assert a.asked >= 1 and b.resent >= 1 and not a.written_off and not b.written_off
    finally:
        for rb in robots:
            rb.close()
