"""The warnings naming lost robots name the first few and count the rest: they named every
robot of the team on one line (all 40 of ``run-formation --robots 40 --graph complete
--drop-prob 0.9``; up to 1000 robots a run takes)."""

from pipeline.outcome import flag_result

SHOWN = 20  # pipeline.outcome.NAMES_SHOWN


def test_robots_declared_lost_are_counted_beyond_the_first_few():
    lost = {str(k): [k + 1] for k in range(1000)}
    report = flag_result({"after": {"conflictive_sets": 0, "links": 0}, "before": {"links": 9},
                          "faults": {"robots_lost": lost, "messages_dropped": 5,
                                     "links_cut_robot_lost": 9}})
    message = next(w["message"] for w in report["warnings"]
                   if w["code"] == "robots-lost-without-crash")
    first = ", ".join(str(k) for k in range(SHOWN))
    assert message.startswith(f"robot(s) {first} and {1000 - SHOWN} more were declared lost by "
                              "their neighbours although they never crashed (5 messages dropped)")
    assert len(message) < 400


def test_crashed_robots_are_counted_beyond_the_first_few():
    crashed = {str(k): 0 for k in range(30)}
    report = flag_result({"after": {"conflictive_sets": 2, "conflictive_features": 9,
                                    "links": 5}, "before": {"links": 9},
                          "faults": {"crashed": crashed, "links_cut_robot_lost": 0}})
    codes = {w["code"]: w["message"] for w in report["warnings"]}
    first = ", ".join(str(k) for k in range(SHOWN))
    assert f"(robot(s) {first} and 10 more crashed before it ended)" in \
        codes["not-conflict-free"]
    assert codes["robots-lost"].startswith(f"robot(s) {first} and 10 more crashed, were killed")


def test_a_few_lost_robots_are_all_named():
    report = flag_result({"after": {"conflictive_sets": 0, "links": 3}, "before": {"links": 9},
                          "faults": {"crashed": {"4": 2, "1": 0}, "links_cut_robot_lost": 6}})
    message = next(w["message"] for w in report["warnings"] if w["code"] == "robots-lost")
    assert message.startswith("robot(s) 1, 4 crashed, were killed or never took part before the "
                              "consistency stage ended; 6 link(s) to them")
