"""A team's observer on a Unix socket (``unixsock-stream//ABSOLUTE/PATH``): robots on this
machine reach it whatever network they are on (each in a network namespace of its own,
:mod:`pipeline.team.netns`), where a ``tcp/HOST:PORT`` observer is reachable only from the
network it listens on. A relative path, or one longer than a socket's, is refused when the file
is read."""

import dataclasses

import pytest
from zygote_teams import EDGES, FPC, LINKS

from pipeline.errors import InputError
from pipeline.team.launcher import launch_team, make_team
from pipeline.team.teamfile import UNIX_PATH_MAX, parse_team


def _doc(observer):
    return {"version": 1, "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7000"},
                                     {"id": 1, "endpoint": "tcp/127.0.0.1:7001"}],
            "comm_edges": [[0, 1]], "observer": {"endpoint": observer},
            "data": {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1]}}


def test_an_absolute_socket_path_is_read_and_written_back():
    team = parse_team(_doc("unixsock-stream//tmp/fm/obs.sock"))
    assert team.observer == "unixsock-stream//tmp/fm/obs.sock"
    assert team.to_json()["observer"] == {"endpoint": "unixsock-stream//tmp/fm/obs.sock"}


@pytest.mark.parametrize("endpoint, named", [
    ("unixsock-stream/obs.sock", "a Unix socket is unixsock-stream//ABSOLUTE/PATH"),
    ("unixsock-stream//tmp/fm/", "a Unix socket is unixsock-stream//ABSOLUTE/PATH"),
    ("unixsock-stream//tmp/" + "x" * UNIX_PATH_MAX, f"has at most {UNIX_PATH_MAX} bytes"),
])
def test_a_socket_path_zenoh_cannot_listen_on_is_refused(endpoint, named):
    with pytest.raises(InputError, match=f"observer endpoint '{endpoint}': .*{named}"):
        parse_team(_doc(endpoint))


def test_a_tcp_observer_refused_names_the_socket_form_too():
    with pytest.raises(InputError, match=r"must look like tcp/HOST:PORT with a port in "
                                         r"1\.\.65535 \(or unixsock-stream//ABSOLUTE/PATH"):
        parse_team(_doc("unix//tmp/obs.sock"))


def test_the_robots_publish_to_an_observer_on_a_socket(tmp_path):
    """A team of four robot processes whose observer listens on a Unix socket: every result
    arrives and is acknowledged, as over TCP."""
    links = tmp_path / "in.csv"
    links.write_text(LINKS)
    data = {"kind": "links", "links": str(links), "features_per_camera": FPC}
    team = make_team("on-a-socket", EDGES, data, {"round_timeout_s": 20.0}, n=4)
    sock = tmp_path / "obs.sock"
    team = parse_team(dataclasses.replace(team, observer=f"unixsock-stream/{sock}").to_json())
    run = launch_team(team, tmp_path / "team", timeout_s=120)
    assert sorted(run.results) == [0, 1, 2, 3]
    assert run.exit_codes == {0: 0, 1: 0, 2: 0, 3: 0}
    logs = [(tmp_path / "team" / f"robot{i}.log").read_text() for i in range(4)]
    assert not any("observer did not acknowledge" in text for text in logs)
