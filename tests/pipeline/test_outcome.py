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


# ------------------------------------------------- the warnings printed, kept in the report

def test_the_warnings_printed_during_a_run_are_kept_in_its_report_once():
    """A warning a ``pipeline`` logger printed within ``recording_warnings`` is added to the
    report (code ``logged``, the ``warning: `` prefix dropped, a repeat once) and not printed
    again by ``exit_status``; outside the block nothing is kept."""
    import logging

    from pipeline.outcome import flag_online, recording_warnings

    log = logging.getLogger("pipeline.somewhere")
    clean = {"links": 5, "after": {"links": 5, "conflictive_sets": 0}}
    with recording_warnings():
        log.warning("warning: %s", "3 file(s) left out")
        log.warning("warning: %s", "3 file(s) left out")
        log.info("a stage line")
        report = flag_result(dict(clean))
        online = flag_online({"steps": [{}], "final": {"links": 4, "online": {"kept": 4}}})
    assert report["warnings"] == [{"code": "logged", "message": "3 file(s) left out"}]
    assert online["warnings"] == report["warnings"]
    out = io.StringIO()
    assert exit_status(report, out) == 0 and out.getvalue() == ""
    log.warning("warning: %s", "after the run")
    assert "warnings" not in flag_result(dict(clean))


def test_a_photo_run_report_names_the_files_it_left_out(tmp_path, capsys):
    """run-images on a folder with a sub-folder of images and a link leading nowhere: the
    warning printed on stderr is in report.json too (it was on stderr only)."""
    import json
    import shutil
    from pathlib import Path

    from pipeline.__main__ import main

    small = Path(__file__).resolve().parents[1] / "data" / "graffiti_small"
    photos = tmp_path / "photos"
    (photos / "sub").mkdir(parents=True)
    for name in ("img1.png", "img2.png"):
        shutil.copy(small / name, photos / name)
    shutil.copy(small / "img3.png", photos / "sub" / "img3.png")
    (photos / "gone.png").symlink_to(tmp_path / "nowhere.png")
    out = tmp_path / "run"
    assert main(["run-images", str(photos), "--max-size", "160", "--no-rerun", "--no-fusion",
                 "--out", str(out), "-q"]) == 0
    err = capsys.readouterr().err
    printed = [line.removeprefix("warning: ") for line in err.splitlines()
               if "left out" in line]
    assert len(printed) == 1 and "gone.png" in printed[0] and "sub" in printed[0]
    report = json.loads((out / "report.json").read_text())
    assert {"code": "logged", "message": printed[0]} in report["warnings"]


def test_void_frames_are_named_as_such_not_as_images_without_features():
    """A frame whose robot the step's matching lost twice has no features: the online
    report names it under ``frames-void``, and a blank frame still under ``no-features``."""
    from pipeline.outcome import exit_status, flag_online

    report = flag_online({"steps": [{"match_frames_void": []}, {"match_frames_void": [3]}],
                          "final": {"links": 4, "online": {"kept": 4}},
                          "features_per_camera": [5, 0, 5, 0, 5]},
                         names=["a", "b", "c", "d", "e"])
    codes = {w["code"]: w["message"] for w in report["warnings"]}
    assert sorted(codes) == ["frames-void", "no-features"]
    assert "d" in codes["frames-void"] and "1 frame(s)" in codes["frames-void"]
    assert "1 image(s): b " in codes["no-features"]
    assert exit_status(report, stream=io.StringIO()) == 0
