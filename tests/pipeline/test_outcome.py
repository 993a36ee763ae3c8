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


def test_a_links_file_without_links_is_not_blamed_on_images(tmp_path, capsys):
    """resolve on a header-only file, over either transport: the warning names the file, not
    images (it has none), and no team of processes is started for nothing (over Zenoh it
    used to fail with a team of 0 robots)."""
    from pipeline.__main__ import main

    src = tmp_path / "in.csv"
    src.write_text("cam_i,feat_i,cam_j,feat_j\n")
    for transport in ("sim", "zenoh"):
        out = tmp_path / f"{transport}.csv"
        assert main(["resolve", "--links", str(src), "--out", str(out), "--transport",
                     transport]) == 0
        err = capsys.readouterr().err
        assert "the links file holds no link row" in err and "images too small" not in err
        assert out.read_text().splitlines() == ["cam_i,feat_i,cam_j,feat_j,status,reason,"
                                                "round,truth"]


def test_links_all_cut_and_links_kept():
    assert _codes({"links": 5, "after": {"links": 0, "conflictive_sets": 0}}) == \
        ["all-links-cut"]
    assert _codes({"links": 5, "after": {"links": 3, "conflictive_sets": 0}}) == []
    assert _codes({"after": {"links": 3, "conflictive_sets": 0}}) == []  # count unknown


def test_one_link_cut_is_said_in_the_singular():
    one = flag_result({"links": 1, "after": {"links": 0, "conflictive_sets": 0}})
    assert one["warnings"][0]["message"].startswith("the one input link was cut;")
    five = flag_result({"links": 5, "after": {"links": 0, "conflictive_sets": 0}})
    assert five["warnings"][0]["message"].startswith("every one of the 5 input links was cut;")
