"""A robot that sends its last round packet and ends at once: its neighbour hears the session
close on one callback thread while the packet, already received, is still being decoded on
another. The neighbour wrote it off (``closed``) with the packet in hand and lost the round's
messages (an online run's matching then stopped: "the features of frame F never came from
robot K"); it now waits CLOSED_GRACE_S for a packet still on its way."""

import threading

import numpy as np

import pipeline.transport.zenoh_transport as zt
from pipeline.team.launcher import make_team


def test_the_last_packet_of_a_robot_that_ended_is_not_lost(monkeypatch):
    team = make_team("lastpacket", [[0, 1]], {"kind": "links", "links": "in.csv",
                                              "features_per_camera": [1, 1]}, n=2)
    robots = [zt.ZenohTransport(team, i, round_timeout_s=30.0, log=lambda s: None)
              for i in range(2)]
    threads = [threading.Thread(target=r.handshake, kwargs={"timeout_s": 30.0}) for r in robots]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    a, b = robots
    slow = threading.Event()
    decode = zt.decode_packet

    def slow_decode(data):  # robot 1 decodes robot 0's packet slowly (a large one, under load)
        header, msgs = decode(data)
        if header["src"] == 0:
            slow.set()
            threading.Event().wait(0.8)
        return header, msgs

    monkeypatch.setattr(zt, "decode_packet", slow_decode)
    got = []

    def receive():
        b.send(0, "x", {"v": np.array([1])})
        inbox, _ = b.end_round()
        got.extend(int(m.payload["v"][0]) for m in inbox)

    t = threading.Thread(target=receive)
    t.start()
    try:
        a.send(1, "x", {"v": np.array([7])})
        a.end_round()          # robot 0 has robot 1's packet: its round is over
        assert slow.wait(20.0)
        a.close()              # and it ends while robot 1 is still decoding its packet
        t.join(60.0)
        assert not t.is_alive()
        assert got == [7] and 0 not in b.written_off, (got, b.written_off)
    finally:
        b.close()
