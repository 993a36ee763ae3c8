"""A team file's endpoint port written in other scripts' digits (``tcp/HOST:٧٤٤٧``) is
refused when the file is read: it was taken (Python's int() reads it as 7447) and Zenoh then
refused it when the robot opened its session ('invalid port value')."""

import pytest

from pipeline.errors import InputError
from pipeline.team.teamfile import parse_team


def _doc(robot_ep="tcp/127.0.0.1:7000", observer_ep=None):
    doc = {"version": 1, "robots": [{"id": 0, "endpoint": robot_ep},
                                    {"id": 1, "endpoint": "tcp/127.0.0.1:7001"}],
           "comm_edges": [[0, 1]],
           "data": {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1]}}
    if observer_ep:
        doc["observer"] = {"endpoint": observer_ep}
    return doc


@pytest.mark.parametrize("port", ["\u0667\u0664\u0664\u0667", "7\uff10\uff10\uff10"])
def test_a_port_not_written_in_digits_is_refused(port):
    with pytest.raises(InputError, match="robot 0 endpoint .* must look like tcp/HOST:PORT"):
        parse_team(_doc(robot_ep=f"tcp/127.0.0.1:{port}"))
    with pytest.raises(InputError, match="observer endpoint .* must look like tcp/HOST:PORT"):
        parse_team(_doc(observer_ep=f"tcp/127.0.0.1:{port}"))


def test_a_port_in_digits_is_read():
    assert parse_team(_doc(observer_ep="tcp/127.0.0.1:7400")).observer == "tcp/127.0.0.1:7400"
