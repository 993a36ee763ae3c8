"""Zenoh's shared memory between robot processes of one host: off unless the team option
``shared_memory`` turns it on (pipeline.transport.zenoh_transport.zenoh_config; on, it was
most of a robot's private memory, bench/team_memory.py)."""

import pytest

from pipeline.team.launcher import make_team
from pipeline.transport import zenoh_transport
from pipeline.transport.zenoh_transport import zenoh_config


def _shm(config) -> str:
    return config.get_json("transport/shared_memory/enabled")


def test_a_session_keeps_off_shared_memory_unless_asked():
    assert _shm(zenoh_config(["tcp/127.0.0.1:1"], [])) == "false"
    assert _shm(zenoh_config(["tcp/127.0.0.1:1"], [], shared_memory=True)) == "true"
    # with a round timeout: both the link's lease and the shared-memory setting
    both = zenoh_config(["tcp/127.0.0.1:1"], [], round_timeout_s=45.0)
    assert _shm(both) == "false" and both.get_json("transport/link/tx/lease") == "100000"


class _Opened(Exception):
    pass


@pytest.mark.parametrize("option", [None, False, True])
def test_a_robot_opens_its_session_with_the_team_option(monkeypatch, option):
    from pipeline.team.robot import run_robot_process

    seen = []

    def opening(listen, connect, who, round_timeout_s=None, shared_memory=False):
        seen.append(shared_memory)
        raise _Opened

    monkeypatch.setattr(zenoh_transport, "open_session", opening)
    options = {} if option is None else {"shared_memory": option}
    team = make_team("shm", [[0, 1]], {"kind": "links", "links": "in.csv",
                                       "features_per_camera": [1, 1]}, options, n=2)
    with pytest.raises(_Opened):
        run_robot_process(team, 0)
    assert seen == [bool(option)]
