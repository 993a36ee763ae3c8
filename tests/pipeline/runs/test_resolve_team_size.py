"""resolve over zenoh refuses a team too large for one machine, naming where its cameras
come from (pipeline.runs.resolve)."""

import pytest

from pipeline.errors import InputError
from pipeline.runs.resolve import resolve_file
from pipeline.runs.transports.zenoh import MAX_ROBOT_PROCESSES


def test_cameras_of_the_comm_graph_are_named_with_it(tmp_path):
    # one link between two cameras; the comm graph is what names the other cameras
    n = MAX_ROBOT_PROCESSES + 10
    links = tmp_path / "one.csv"
    links.write_text("0,0,1,0\n")
    graph = tmp_path / "graph.csv"
    graph.write_text("".join(f"{i},{i + 1}\n" for i in range(n - 1)))
    with pytest.raises(InputError) as err:
        resolve_file(links, tmp_path / "out.csv", graph, transport="zenoh")
    assert f"{n} cameras in the links file and the comm graph would be {n} processes" \
        in str(err.value)
    assert not (tmp_path / "out.csv").exists()
