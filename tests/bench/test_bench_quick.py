"""A bench's --quick picks small values only for the options not given: with an option given
(--quick --frames 3) it ran its own quick value instead, silently (landmarks_clear then
refused a small data folder for 20 frames the user had not asked for)."""

import json
from pathlib import Path

from benchload import load_bench

ROOT = Path(__file__).resolve().parents[2]
HOTEL = ROOT / "tests" / "data" / "cmu_hotel_small"


def test_faults_quick_keeps_formations(tmp_path, monkeypatch, capsys):
    bench = load_bench("faults")
    monkeypatch.setattr(bench, "OUT", tmp_path)
    assert bench.main(["--quick", "--formations", "1"]) == 0
    assert json.loads((tmp_path / "results.json").read_text())["formations"] == 1


def test_consistency_scale_quick_keeps_n(tmp_path, capsys, monkeypatch):
    import importlib.util

    bench = load_bench("consistency_scale")
    bench.plot = lambda records, path: None  # the figure is not what is tested
    # nor is matplotlib, which the bench extra brings and the tests' install lacks
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: True if name == "matplotlib" else find_spec(name, *a))
    assert bench.main(["--quick", "--n", "6", "--repeat", "1", "--resolution", "paper",
                       "--features", "40", "--per-robot-max-n", "0", "--out", str(tmp_path)]) == 0
    records = json.loads((tmp_path / "results.json").read_text())["records"]
    assert [r["n"] for r in records] == [6]


def test_landmarks_clear_quick_keeps_frames(tmp_path, capsys):
    bench = load_bench("landmarks_clear")
    assert bench.main(["--quick", "--frames", "3", "--data", str(HOTEL), "--graphs", "ring",
                       "--configs", "none:none:none", "--out", str(tmp_path)]) == 0
    records = json.loads((tmp_path / "results.json").read_text())["records"]
    assert {r["frames"] for r in records} == {3}


def test_multiway_quick_keeps_what_is_given(tmp_path, capsys):
    bench = load_bench("multiway")
    assert bench.main(["--quick", "--data", str(HOTEL), "--frames", "4", "--graphs", "ring2",
                       "--warped-seeds", "--team", "5", "--methods", "sync",
                       "--team-methods", "sync", "--out", str(tmp_path)]) == 0
    got = json.loads((tmp_path / "results.json").read_text())
    args = got["args"]
    assert (args["frames"], args["graphs"], args["warped_seeds"], args["team"]) == (
        [4], ["ring2"], [], [5])
    # what was not given is --quick's
    assert (args["inputs"], args["graffiti"], args["formations"]) == (["descriptors"], "", "a")
    assert {(r["case"], r.get("frames"), r.get("cameras")) for r in got["records"]
            if r["case"] != "formation"} == {("landmarks", 4, None), ("team", None, 5)}


def test_images_vs_colmap_quick_keeps_rings(tmp_path, monkeypatch, capsys):
    bench = load_bench("images_vs_colmap")
    asked = []

    def inputs(folders, kinds, tmp, rings, *rest):
        asked.append((folders, rings))
        return iter(())
    monkeypatch.setattr(bench, "_inputs", inputs)
    out = tmp_path / "results.json"
    assert bench.main(["--quick", "--rings", "AABB", "--out", str(out)]) == 0
    assert asked == [([bench.QUICK_DATA], ["AABB"])]
