"""team_summary (pipeline.team.launcher): the report's team section names the comm-graph
pairs that a robot which published never matched."""

from pipeline.team.launcher import TeamRun, make_team, team_summary


def _result(i, pairs):
    counters = {k: 0 for k in ("round", "messages", "bytes", "wire_bytes", "wire_packets",
                               "dropped", "silent")}
    return ({"id": i, "counters": counters, "peak_rss_bytes": 0, "peak_memory_bytes": 0,
             "timings_s": {}, "matches": [{"i": a, "j": b} for a, b in pairs]}, {})


def test_a_pair_a_robot_never_matched_is_named():
    """Line 0-1-2-3: robots 1 and 2 wrote each other off before their features crossed
    (neither matched the other); robot 3 never published, and robot 2 matched it."""
    team = make_team("line", [[0, 1], [1, 2], [2, 3]],
                     {"kind": "formation", "formation": "line", "robots": 4, "seed": 0,
                      "size": [160, 120]}, n=4)
    run = TeamRun(team, results={0: _result(0, [(0, 1)]), 1: _result(1, [(0, 1)]),
                                 2: _result(2, [(2, 3)])})
    assert team_summary(run)["unmatched_pairs"] == [[1, 2]]
    run.results[1] = _result(1, [(0, 1), (1, 2)])
    run.results[2] = _result(2, [(1, 2), (2, 3)])
    assert "unmatched_pairs" not in team_summary(run)
