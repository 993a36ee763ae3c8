"""A team file's seeds and feature count take the command line's ranges: run-formation refuses
``--seed 2**63`` and ``--max-features 7``, and so does TEAM.json, naming the file, the field and
the value."""
import pytest

from pipeline.errors import InputError
from pipeline.team.teamfile import parse_team

_FORMATION = {"kind": "formation", "formation": "d", "seed": 0, "size": [640, 480],
              "robots": None, "graph": "complete"}


def _doc(data=None, options=None):
    doc = {"version": 1, "name": "t", "comm_edges": [[i, j] for i in range(6) for j in range(i + 1, 6)],
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(6)],
           "data": {**_FORMATION, **(data or {})}}
    if options:
        doc["options"] = options
    return doc


@pytest.mark.parametrize("data, options, words", [
    ({"seed": 2**63}, None, f"data.seed {2**63}: a seed must be an integer from 0 to 2**63 - 1"),
    (None, {"fault_seed": 2**64}, f"option fault_seed {2**64}: a seed must be an integer from 0"),
    (None, {"max_features": 7}, "option max_features 7: at least 8 are needed"),
    (None, {"max_features": 1}, "option max_features 1: at least 8 are needed"),
    (None, {"max_features": 10**6 + 1}, "option max_features 1000001: at most 1000000 per image; "
     "give a smaller count (e.g. 2000) or null for photos"),
    (None, {"max_features": "2000"}, "option max_features '2000' must be an integer in 8..1000000 "
     "or null"),
])
def test_a_team_file_refuses_what_the_command_line_refuses(tmp_path, data, options, words):
    with pytest.raises(InputError) as exc:
        parse_team(_doc(data, options), tmp_path / "TEAM.json")
    assert "TEAM.json" in str(exc.value) and words in str(exc.value)


def test_a_team_file_takes_the_command_line_bounds(tmp_path):
    team = parse_team(_doc({"seed": 2**63 - 1}, {"max_features": 8, "fault_seed": 2**63 - 1}),
                      tmp_path / "TEAM.json")
    assert team.data["seed"] == 2**63 - 1 and team.options_for(0)["max_features"] == 8
    assert parse_team(_doc(options={"max_features": None})).options_for(0)["max_features"] is None


def _team_of(n: int, robots) -> dict:
    return {"version": 1, "name": "t", "comm_edges": [[i, i + 1] for i in range(n - 1)],
            "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{7000 + i}"} for i in range(n)],
            "data": {**_FORMATION, "formation": "line", "robots": robots, "graph": "line"}}


def test_a_team_file_refuses_more_robots_than_run_formation(tmp_path):
    """run-formation --robots takes 2 to 1000; a team file of 1001 robots was accepted and
    every robot then failed in data_synth."""
    with pytest.raises(InputError) as exc:
        parse_team(_team_of(1001, 1001), tmp_path / "TEAM.json")
    assert "TEAM.json" in str(exc.value)
    assert "data.robots 1001: give a number of robots from 2 to 1000" in str(exc.value)
    with pytest.raises(InputError, match=r"data.robots True must be an integer from 2 to 1000"):
        parse_team(_team_of(2, True), tmp_path / "TEAM.json")


def test_a_team_file_takes_run_formation_s_most_robots(tmp_path):
    assert parse_team(_team_of(1000, 1000), tmp_path / "TEAM.json").n == 1000
