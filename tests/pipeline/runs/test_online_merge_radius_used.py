"""run-formation --steps: report.json's config records merge_radius_used_px, the radius the
keypoints were merged at; merge_radius null (the default) said nothing of the 0.5 px an
online run merges at, whatever the rule (a batch run merges at the rule's own radius)."""

import json

import pytest

from pipeline.__main__ import main

FAST = ["--size", "160x120", "--max-features", "150", "--formation", "a", "--steps", "1",
        "--no-rerun", "--no-fusion", "-q"]


def _report(tmp_path, name, *extra):
    out = tmp_path / name
    assert main(["run-formation", *FAST, "--out", str(out), *extra]) == 0
    return json.loads((out / "report.json").read_text())


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    return _report(tmp_path_factory.mktemp("online-radius"), "default")


def test_the_default_radius_is_recorded_as_the_one_used(default_run, tmp_path):
    assert default_run["config"]["merge_radius"] is None
    assert default_run["config"]["merge_radius_used_px"] == 0.5
    given = _report(tmp_path, "given", "--merge-radius", "0.5")
    assert given["config"]["merge_radius_used_px"] == 0.5
    # the same features: 0.5 px is the radius the default run merged at
    assert given["features_per_camera"] == default_run["features_per_camera"]


@pytest.mark.parametrize("radius,rule", [("0", "evidence"), ("3", "paper")])
def test_a_given_radius_is_recorded(tmp_path, radius, rule):
    report = _report(tmp_path, "run", "--merge-radius", radius, "--resolution", rule)
    assert report["config"]["merge_radius_used_px"] == float(radius)
