"""The warnings a run's report carries (pipeline.outcome.flag_result) and the exit status."""

import io

from pipeline.outcome import exit_status, flag_result


def _codes(report):
    return [w["code"] for w in flag_result(report).get("warnings", [])]


def test_an_input_without_links_is_said_not_silently_empty():
    report = {"before": {"links": 0}, "after": {"links": 0, "conflictive_sets": 0}}
    assert _codes(report) == ["no-links"]
    out = io.StringIO()
    assert exit_status(report, out) == 0  # a warning, not a failure
    assert "nothing to associate" in out.getvalue()


def test_links_all_cut_and_links_kept():
    assert _codes({"links": 5, "after": {"links": 0, "conflictive_sets": 0}}) == \
        ["all-links-cut"]
    assert _codes({"links": 5, "after": {"links": 3, "conflictive_sets": 0}}) == []
    assert _codes({"after": {"links": 3, "conflictive_sets": 0}}) == []  # count unknown
