"""The online run's ``no-links`` warning blames the speed only where frames left the scene: it
named the default --speed 0.15 as a likely cause of every online run without a link (frames
of 64x48 pixels with 8 features, driven 0.15 m in all), though the robots of one step see the
scene alike at any speed; a frame driven beside the scene sees only sky and has no feature."""

import json

import pytest

from pipeline.__main__ import main


@pytest.mark.parametrize("speed, blamed", [(None, False), ("1000", True)])
def test_no_links_warning_names_the_speed_only_when_frames_left_the_scene(
        tmp_path, capsys, speed, blamed):
    out = tmp_path / "run"
    args = ["run-formation", "--steps", "2", "--size", "64x48", "--max-features", "8",
            "--no-fusion", "--no-rerun", "-q", "--out", str(out)]
    assert main(args + (["--speed", speed] if speed else [])) == 0
    err = capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    no_links = next(w["message"] for w in report["warnings"] if w["code"] == "no-links")
    assert no_links.startswith("no link in 2 steps: there is nothing to associate (frames too "
                               "small, too few features")
    assert ("the formation may have left the scene" in no_links) is blamed
    assert (0 in report["features_per_camera"]) is blamed
    assert no_links in err
