"""The Zenoh transport's round clock: a round packet lost on the way is asked for again and
sent again, so the round completes (pipeline.transport.zenoh_transport, "A round packet
lost")."""

import json
import threading
import time

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


class _LossyHello:
    """A robot's Zenoh session whose ``hello`` puts pass only when ``keep(doc)`` says so."""

    def __init__(self, session, keep):
        self._session, self._keep, self.dropped = session, keep, []

    def put(self, key_expr, payload):
        if "/hello/" in str(key_expr):
            doc = json.loads(payload)
            if not self._keep(doc):
                self.dropped.append(doc)
                return None
        return self._session.put(key_expr, payload)

    def __getattr__(self, name):
        return getattr(self._session, name)


class _DeafHello(_LossyHello):
    """A robot's Zenoh session whose ``hello`` puts all say it heard nobody (``heard`` false):
    its neighbours hear it, but never learn that it heard them."""

    def __init__(self, session):
        super().__init__(session, lambda doc: True)

    def put(self, key_expr, payload):
        if "/hello/" in str(key_expr):
            payload = json.dumps({**json.loads(payload), "heard": False})
        return self._session.put(key_expr, payload)


def _pair(name):
    team = make_team(name, [[0, 1]], {"kind": "links", "links": "in.csv",
                                      "features_per_camera": [1, 1]}, n=2)
    return [ZenohTransport(team, i, round_timeout_s=30.0, log=lambda s: None) for i in range(2)]


def test_a_lost_last_hello_is_answered_again():
    """Robot 0's hellos that say it heard robot 1 are lost, its last one included (as when a
    robot is killed before Zenoh sends it): robot 1 still finishes its handshake, at once and
    without writing robot 0 off, because robot 0 answers its hellos once it has started."""
    robots = _pair("lasthello")
    first = []

    def keep(doc):  # lose every "heard you" of the handshake loop and the last hello
        if not doc["heard"]:
            return True
        if doc["done"] and not first:
            first.append(doc)
            return False
        return bool(doc["done"])

    robots[0].session = _LossyHello(robots[0].session, keep)
    took = [None, None]

    def run(i):
        took[i] = robots[i].handshake(timeout_s=20.0)

    try:
        threads = [threading.Thread(target=run, args=(i,)) for i in (0, 1)]
        # robot 1 starts once it has heard robot 0 (a hello saying "not heard you yet", the
        # only kind that is not lost): started together, robot 0 could hear robot 1 before its
        # first hello, and then every hello it sends says "heard you" and is lost, so neither
        # ever hears the other (a race of the test's loss pattern, not of the protocol)
        threads[0].start()
        deadline = time.monotonic() + 20.0
        while 0 not in robots[1]._hello and time.monotonic() < deadline:
            time.sleep(0.01)
        threads[1].start()
        for t in threads:
            t.join(60)
        assert first, "the test did not lose the last hello"
        assert not robots[1].written_off and not robots[0].written_off
        assert took[1] is not None and took[1] < 10.0
    finally:
        for rb in robots:
            rb.close()


def test_a_neighbour_heard_then_gone_is_written_off_in_the_handshake():
    """Robot 1 never learns that robot 0 heard it (every such hello lost); robot 0 then ends:
    robot 1 writes it off as ``closed`` when its session closes, not at the start timeout."""
    robots = _pair("heardgone")
    # every hello says "not heard" (dropping those that said "heard" instead raced: when robot
    # 1's first hello reached robot 0 before robot 0's first, robot 1 heard nothing at all)
    robots[0].session = _DeafHello(robots[0].session)
    took = [None, None]

    def run(i):
        took[i] = robots[i].handshake(timeout_s=30.0)

    t1 = threading.Thread(target=run, args=(1,))
    t1.start()
    try:
        run(0)
        time.sleep(0.5)
        robots[0].close()
        t1.join(60)
        assert robots[1].written_off == {0: "closed"}
        assert took[1] is not None and took[1] < 20.0
    finally:
        robots[1].close()


def test_robots_started_with_team_files_of_other_rules_both_stop_in_the_handshake():
    """Robot 1's team file names another rule than robot 0's (a TEAM.json edited between
    robots): both stop at the start with an InputError naming the setting, where they used
    to run their different protocols without ever ending a phase."""
    import dataclasses

    import pytest

    from pipeline.errors import InputError

    team = make_team("otherterms", [[0, 1]], {"kind": "links", "links": "in.csv",
                                              "features_per_camera": [1, 1]}, n=2)
    other = dataclasses.replace(team, options={**team.options, "resolution": "paper"})
    robots = [ZenohTransport(t, i, round_timeout_s=30.0, log=lambda s: None)
              for i, t in ((0, team), (1, other))]
    errors = [None, None]

    def run(i):
        try:
            robots[i].handshake(timeout_s=20.0)
        except InputError as exc:
            errors[i] = str(exc)

    try:
        threads = [threading.Thread(target=run, args=(i,)) for i in (0, 1)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        assert "resolution 'paper' there, 'evidence' here" in errors[0]
        assert "resolution 'evidence' there, 'paper' here" in errors[1]
        with pytest.raises(InputError, match="another team file"):
            robots[1].handshake(timeout_s=1.0)
    finally:
        for rb in robots:
            rb.close()


class _CountedHellos:
    """A robot's Zenoh session that counts its ``hello`` puts per neighbour."""

    def __init__(self, session):
        self._session, self.to = session, {}

    def put(self, key_expr, payload):
        if "/hello/" in str(key_expr):
            dst = int(str(key_expr).rsplit("/", 1)[1])
            self.to[dst] = self.to.get(dst, 0) + 1
        return self._session.put(key_expr, payload)

    def __getattr__(self, name):
        return getattr(self._session, name)


def test_hellos_to_a_neighbour_that_never_starts_are_paced():
    """Robot 0 waits 3 s for robot 2, which never starts: its hellos to robot 2 come ever
    more slowly (0.05 s, doubling up to 1 s: about 7), where it sent one on every turn of its
    loop (every 0.05 s at most, and on every hello it received: 60 or more), a cost that
    grew with the square of a robot's neighbours in a dense team."""
    team = make_team("paced", [[0, 1], [0, 2]], {"kind": "links", "links": "in.csv",
                                                  "features_per_camera": [1, 1, 1]}, n=3)
    robots = [ZenohTransport(team, i, round_timeout_s=30.0, log=lambda s: None)
              for i in range(2)]
    counted = robots[0].session = _CountedHellos(robots[0].session)
    errors = []

    def run(i):
        try:
            robots[i].handshake(timeout_s=3.0)
        except Exception as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        assert not errors, errors
        assert robots[0].written_off == {2: "start"} and not robots[1].written_off
        assert 3 <= counted.to[2] <= 12, counted.to
        assert counted.to[1] <= 12, counted.to
    finally:
        for r in robots:
            r.close()


def test_the_beat_period_follows_the_round_timeout():
    """A thirtieth of the silence that writes a neighbour off, from 0.2 s to 5 s: every 1 s at
    the default 30 s, where it was 0.2 s whatever the timeout (500 beats a second from a
    robot with 100 neighbours)."""
    from pipeline.transport.zenoh_transport import beat_period

    assert beat_period(30.0) == 1.0
    assert beat_period(2.0) == 0.2 and beat_period(0.5) == 0.2
    assert beat_period(3600.0) == 5.0
    team = make_team("beats", [[0, 1]], {"kind": "links", "links": "in.csv",
                                         "features_per_camera": [1, 1]}, n=2)
    robot = ZenohTransport(team, 0, round_timeout_s=60.0, log=lambda s: None)
    try:
        assert robot.beat_s == 2.0
    finally:
        robot.close()
