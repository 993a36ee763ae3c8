"""The ports a team is given: free, distinct, and outside the kernel's ephemeral range."""

import socket

from pipeline.team.launcher import ephemeral_range, free_ports, make_team


def test_ports_are_free_distinct_and_below_the_ephemeral_range():
    lo, hi = ephemeral_range()
    assert 1024 <= lo <= hi
    ports = free_ports(40)
    assert len(set(ports)) == 40
    # the kernel hands ports of [lo, hi] to bind(0) and to outgoing connections: a robot's
    # port drawn there could be taken before the robot binds it
    assert all(p < lo for p in ports), sorted(ports)[-3:]
    for p in ports:
        with socket.socket() as s:
            s.bind(("127.0.0.1", p))


def test_a_team_gets_its_robots_and_observer_ports_from_there(tmp_path):
    team = make_team("t", [[0, 1], [1, 2]], {"kind": "links", "links": str(tmp_path / "l.csv"),
                                              "features_per_camera": [2, 2, 2]}, n=3)
    ports = [int(r.endpoint.rsplit(":", 1)[1]) for r in team.robots]
    ports.append(int(team.observer.rsplit(":", 1)[1]))
    assert len(set(ports)) == 4
    assert max(ports) < ephemeral_range()[0]
