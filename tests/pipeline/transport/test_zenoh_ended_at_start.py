"""A neighbour whose process ended while starting, before this robot heard it: a launcher
that saw it end declares an ``ended`` token for it (:meth:`pipeline.team.launcher.Observer.
ended`), and with ``closed_unheard`` (the launcher's teams: option ``closed_at_start``) the
robot writes it off at once as ``closed`` instead of waiting out the start handshake
(pipeline.transport.zenoh_transport, "Start handshake")."""

import pytest

from pipeline.team.launcher import Observer, make_team
from pipeline.transport import RobotMissingError
from pipeline.transport.zenoh_transport import ZenohTransport

DATA = {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1, 1]}


def _handshake(team, closed_unheard: bool, timeout_s: float):
    observer = Observer(team)  # the launcher's, which saw robot 1's process end
    observer.ended(1)
    robot = ZenohTransport(team, 0, round_timeout_s=30.0, log=lambda s: None)
    try:
        robot.handshake(timeout_s=timeout_s, closed_unheard=closed_unheard)
        return dict(robot.written_off)
    finally:
        robot.close()
        observer.close()


def test_a_neighbour_that_ended_unheard_is_written_off_at_once():
    """Robot 0's only neighbour, robot 1, never said hello: its launcher's token says its
    process ended, so robot 0 writes it off as ``closed`` well within the 60 s it would
    otherwise wait (the handshake would then fail: no neighbour heard)."""
    team = make_team("ended", [[0, 1], [1, 2]], DATA, n=3)
    assert team.options["closed_at_start"] is True
    assert _handshake(team, True, 60.0) == {1: "closed"}


def test_without_closed_unheard_it_is_waited_for():
    """A hand-started team (no ``closed_at_start``): robot 1 may still be started by hand
    and join, so robot 0 waits out its start timeout (here 2 s) and, having heard no
    neighbour, stops."""
    team = make_team("ended", [[0, 1], [1, 2]], DATA, {"closed_at_start": False}, n=3)
    with pytest.raises(RobotMissingError, match="robot 1 .* did not answer within 2 s"):
        _handshake(team, False, 2.0)
