"""flag_result on the report of a team of robot processes (zenoh): a robot written off
while it ran to its end is warned of; a robot that died is not (pipeline.outcome)."""

from pipeline.outcome import flag_result

RAN = {"rounds": 18, "messages": 10}


def _team_report(robots, lost=None):
    faults = {"dropped": 0, "crashed": {}, "robots_lost": {"1": [0, 2]},
              "links_cut_robot_lost": 0}
    team = {"transport": "zenoh", "robots": robots}
    if lost is not None:
        team["lost"] = lost
    return {"before": {"links": 40}, "after": {"links": 30, "conflictive_sets": 0},
            "resolution": {"details": {"faults": faults}}, "team": team}


def test_a_robot_written_off_although_it_ran_to_its_end_is_warned_of():
    report = flag_result(_team_report({"0": RAN, "1": RAN, "2": RAN}))
    assert [w["code"] for w in report["warnings"]] == ["robots-lost-without-crash"]
    assert "robot(s) 1 " in report["warnings"][0]["message"]
    assert "conflict_free" not in report


def test_a_robot_that_died_or_never_published_is_no_false_loss_but_a_loss():
    killed = {"result": None, "exit_code": -9, "killed": False, "started": True}
    for report in (flag_result(_team_report({"0": RAN, "1": killed, "2": RAN})),
                   flag_result(_team_report({"0": RAN, "2": RAN}, lost=[1]))):
        assert [w["code"] for w in report["warnings"]] == ["robots-lost"]
        assert report["warnings"][0]["message"].startswith("robot(s) 1 crashed, were killed")
        assert "conflict_free" not in report  # a warning, not a failed result


def test_a_clean_team_has_no_warning():
    report = _team_report({"0": RAN, "1": RAN, "2": RAN})
    report["resolution"]["details"]["faults"]["robots_lost"] = {}
    assert "warnings" not in flag_result(report)


def test_a_simulated_crash_is_warned_with_the_links_it_cost():
    report = {"before": {"links": 40}, "after": {"links": 30, "conflictive_sets": 0},
              "faults": {"crashed": {"0": 0, "1": 0}, "robots_lost": {"0": [1], "1": [0]},
                         "links_cut_robot_lost": 7}}
    w = flag_result(report)["warnings"]
    assert [x["code"] for x in w] == ["robots-lost"]
    assert "robot(s) 0, 1 crashed" in w[0]["message"] and "7 link(s)" in w[0]["message"]


def test_a_robot_that_ran_to_its_end_unheard_by_the_observer_is_not_called_killed():
    """Robot 1 finished with its neighbours (none wrote it off) but its result never reached
    the observer (the observer's cable to it was down): it used to be warned of as crashed,
    killed or never started, with 'rerun without the fault'."""
    report = _team_report({"0": RAN, "2": RAN}, lost=[1])
    report["team"]["unreported"] = [1]
    report["resolution"]["details"]["faults"].update(robots_lost={}, crashed={"1": None})
    w = flag_result(report)["warnings"]
    assert [x["code"] for x in w] == ["robots-unreported"]
    assert w[0]["message"].startswith("robot(s) 1 ran to their end with their neighbours")


def test_a_pair_never_matched_is_warned_of_although_no_link_was_cut():
    """Robot 1 wrote robot 2 off (silent: a cable capped at 16 kbit/s) before their features
    crossed: pair 1-2 was never matched and its links are missing, while the loss warning said
    '0 link(s) were cut as robot-lost'."""
    report = _team_report({"0": RAN, "1": RAN, "2": RAN})
    report["team"]["unmatched_pairs"] = [[1, 2]]
    w = flag_result(report)["warnings"]
    assert [x["code"] for x in w] == ["pairs-unmatched", "robots-lost-without-crash"]
    assert w[0]["message"].startswith("1 image pair(s) of the comm graph were never matched "
                                      "(1-2)")
