"""run-formation --steps N (pipeline.runs.online): the run folder, its step timeline, the
checks of the options."""

import csv
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.__main__ import main
from viz.recording_reader import entity_paths

FAST = ["--size", "192x144", "--max-features", "150", "--formation", "a"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("online") / "run"
    assert main(["run-formation", "--steps", "3", "--window", "2", "--out", str(out),
                 *FAST]) == 0
    return out


def test_report_has_one_entry_per_step(run_dir):
    report = json.loads((run_dir / "report.json").read_text())
    assert [s["step"] for s in report["steps"]] == [0, 1, 2]
    for s in report["steps"]:
        for key in ("links_new", "conflictive_sets_after", "wall_s", "rounds", "bytes",
                    "messages", "robot_memory_bytes_max"):
            assert key in s
        assert s["conflictive_sets_after"] == 0
    assert report["conflict_free_every_step"] is True
    assert report["n_images"] == 18 and report["window"] == 2
    assert report["hold"] == 1  # the default hold, window - 1
    assert sum(s["links_new"] for s in report["steps"]) == report["final"]["links"]
    # the batch run at the last step, scored on the same scope
    assert report["final"]["batch"]["true_pairs"] == report["final"]["online"]["true_pairs"]
    assert report["steps"][-1]["batch"]["conflictive_sets_after"] == 0


def test_links_and_their_steps_agree_with_the_report(run_dir):
    report = json.loads((run_dir / "report.json").read_text())
    with open(run_dir / "links.csv") as f:
        links = list(csv.DictReader(f))
    with open(run_dir / "link_steps.csv") as f:
        steps = list(csv.DictReader(f))
    assert len(links) == len(steps) == report["final"]["links"]
    cut = [int(s["step_cut"]) for s in steps if s["step_cut"]]
    fusion = [r["fusion"]["cut"] for r in report["steps"]]
    assert len(cut) == sum(r["cut"] for r in report["steps"]) + sum(fusion)
    assert report["fusion"]["links_cut"] == sum(fusion)
    assert all(lk["status"] == "deleted" for lk, s in zip(links, steps, strict=True)
               if s["step_cut"])
    for r in report["steps"]:
        assert sum(int(s["step_added"]) == r["step"] for s in steps) == r["links_new"]
        assert cut.count(r["step"]) == r["cut"] + r["fusion"]["cut"]
    with open(run_dir / "images.csv") as f:
        images = list(csv.DictReader(f))
    assert [(int(i["robot"]), int(i["step"])) for i in images][:7] == \
        [(0, 0), (1, 0), (2, 0), (3, 0), (4, 0), (5, 0), (0, 1)]


def test_recording_carries_the_step_timeline(run_dir):
    from rerun.chunk import RrdReader

    paths = entity_paths(run_dir / "recording.rrd")
    for p in ("/world/robots", "/world/links/new", "/steps/links_new",
              "/steps/conflictive_sets_after", "/steps/log"):
        assert p in paths
    store = RrdReader(run_dir / "recording.rrd").store()
    timelines = {str(c) for c in store.schema().index_columns()}
    assert any("step" in t for t in timelines)


@pytest.mark.parametrize("flags, match", [
    (["--steps", "0"], "--steps 0"),
    (["--steps", "2", "--window", "0"], "--window 0"),
    # a speed typed as a whole number is named as typed, not as -1.0
    (["--steps", "2", "--speed", "-1"], "--speed -1: expected a finite number of metres"),
    (["--steps", "2", "--hold", "-1"], "--hold -1"),
    (["--steps", "2", "--drop-prob", "0.1"], "switching-topology"),
    # the graph of each step is drawn from --seed: a --fault-seed changed nothing, silently
    (["--steps", "2", "--switching-topology", "--fault-seed", "7"], "--fault-seed 7: an online"),
    # every frame is rendered before the first step: refused before rendering, not killed
    (["--steps", "1000000"], "rendering 1000000 steps of 6 robots"),
])
def test_bad_options_are_refused(tmp_path, capsys, flags, match):
    assert main(["run-formation", "--out", str(tmp_path / "r"), *FAST, *flags]) == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_a_parametric_online_run_records_no_formation_letter(tmp_path, run_dir):
    """--robots/--graph draw the graph: config.formation is null, not the unused 'd'."""
    out = tmp_path / "line"
    assert main(["run-formation", "--steps", "1", "--robots", "3", "--graph", "line",
                 "--size", "192x144", "--max-features", "150", "--no-fusion", "--no-rerun",
                 "--out", str(out)]) == 0
    assert json.loads((out / "report.json").read_text())["config"]["formation"] is None
    assert json.loads((run_dir / "report.json").read_text())["config"]["formation"] == "a"


def test_without_fusion_no_link_is_cut_as_an_outlier(tmp_path):
    out = tmp_path / "r"
    assert main(["run-formation", "--steps", "2", "--window", "2", "--no-fusion", "--no-rerun",
                 "--out", str(out), *FAST]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["fusion"]["enabled"] is False and report["fusion"]["links_cut"] == 0
    assert all("fusion" not in s for s in report["steps"])
    assert not (out / "recording.rrd").exists()


def test_the_merge_radius_reaches_the_robots_features(tmp_path):
    """--merge-radius with --steps is applied (it was once dropped): a wide radius merges
    keypoints, so the first step's frames have fewer features, and links, than with the
    default."""
    counts = []
    for extra in ([], ["--merge-radius", "12"]):
        out = tmp_path / f"r{len(extra)}"
        assert main(["run-formation", "--steps", "1", "--no-fusion", "--no-rerun", "--out",
                     str(out), *FAST, *extra]) == 0
        report = json.loads((out / "report.json").read_text())
        counts.append(report["steps"][0]["links_new"])
    assert report["config"]["merge_radius"] == 12.0
    assert 0 < counts[1] < counts[0]


def test_a_run_without_any_link_is_warned(tmp_path, capsys):
    """A formation driven off its scene (--speed 100) matches nothing: said, with the speed,
    not an F1 of 0 on 0 pairs in silence."""
    out = tmp_path / "gone"
    assert main(["run-formation", "--steps", "2", "--speed", "100", "--no-fusion", "--no-rerun",
                 "--out", str(out), *FAST]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["final"]["links"] == 0
    err = capsys.readouterr().err
    assert "warning: no link in 2 steps" in err and "--speed 100 m per step" in err
    # in the report too, as a batch run's result warnings are (it was on stderr only)
    assert [w["code"] for w in report["warnings"]] == ["no-links", "no-features"]
    assert "--speed 100 m per step" in report["warnings"][0]["message"]


def test_frames_without_features_are_warned_and_named(tmp_path, capsys):
    """At --speed 12 the formation starts and ends beside the scene: the frames of steps 0
    and 3 see only sky. They are named in a no-features warning and counted in
    features_per_camera, as run-images --sequence does, not left out in silence."""
    out = tmp_path / "beside"
    assert main(["run-formation", "--steps", "4", "--speed", "12", "--robots", "3", "--graph",
                 "ring", "--size", "96x72", "--max-features", "80", "--no-rerun",
                 "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    m = report["features_per_camera"]
    assert len(m) == 12 and [k for k, v in enumerate(m) if v == 0] == [0, 1, 2, 9, 10, 11]
    assert [w["code"] for w in report["warnings"]] == ["no-features"]
    names = "r00k000, r01k000, r02k000, r00k003, r01k003, r02k003"
    assert names in report["warnings"][0]["message"]
    assert f"no features found in 6 image(s): {names}" in capsys.readouterr().err


def test_no_link_because_of_a_wide_merge_radius_names_the_radius(tmp_path, capsys):
    """--merge-radius 144 (the shorter side, the widest allowed) merges each frame's keypoints
    into one feature, so nothing links: the warning named the images and the speed only, where a batch run names the radius."""
    out = tmp_path / "merged"
    assert main(["run-formation", "--steps", "2", "--merge-radius", "144", "--no-fusion",
                 "--no-rerun", "--out", str(out), *FAST]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["final"]["links"] == 0
    message = report["warnings"][0]["message"]
    assert "a --merge-radius of 144 px merging each image's keypoints" in message
    assert message in capsys.readouterr().err


def test_no_link_because_the_switching_graph_had_no_edge_names_the_graph(tmp_path, capsys):
    """Two robots, one step, and the drawn graph of that step has no edge up: nothing could
    be matched, and the warning blamed the images and the speed instead of the graph."""
    out = tmp_path / "apart"
    assert main(["run-formation", "--steps", "1", "--robots", "2", "--graph", "line",
                 "--switching-topology", "--window", "10", "--no-fusion", "--no-rerun",
                 "--out", str(out), "--size", "192x144", "--max-features", "150"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["steps"][0]["comm_edges"] == [] and report["final"]["links"] == 0
    message = report["warnings"][0]["message"]
    assert "--switching-topology left no communication link up in any of the 1 step(s)" in message
    assert "--speed" not in message and message in capsys.readouterr().err


def test_each_step_line_counts_the_links_fusion_cut(tmp_path, capsys):
    """A step's line said "0 cut" where fusion had cut 12 links at that step (links.csv and
    link_steps.csv count them): it now names the fusion's cuts beside the stage's."""
    out = tmp_path / "fused"
    assert main(["run-formation", "--steps", "2", "--resolution", "paper", "--no-rerun",
                 "--out", str(out), *FAST]) == 0
    report = json.loads((out / "report.json").read_text())
    with open(out / "link_steps.csv", newline="") as f:
        cut_at = [r["step_cut"] for r in csv.DictReader(f)]
    err = capsys.readouterr().err
    assert sum(s["fusion"]["cut"] for s in report["steps"]) > 0
    for s in report["steps"]:
        t, stage, fused = s["step"], s["cut"], s["fusion"]["cut"]
        assert stage + fused == cut_at.count(str(t))
        assert f"step {t}: {s['links_new']} new links, {stage} cut, {fused} cut by fusion, " in err


def test_a_still_formation_keeps_the_good_links_between_a_robots_frames(tmp_path):
    """--speed 0: each robot sees its scene from one pose at every step. The evidence rule's
    geometric test refused two observations through one pose by rounding noise, and cut 44
    good links between a robot's two frames (3 robots, 2 steps); none is cut now."""
    out = tmp_path / "still"
    assert main(["run-formation", "--steps", "2", "--speed", "0", "--robots", "3", "--graph",
                 "line", "--size", "160x120", "--max-features", "100", "--no-rerun",
                 "--out", str(out)]) == 0
    with open(out / "images.csv", newline="") as f:
        robot = {int(r["image"]): r["robot"] for r in csv.DictReader(f)}
    with open(out / "links.csv", newline="") as f:
        own = [r for r in csv.DictReader(f) if robot[int(r["cam_i"])] == robot[int(r["cam_j"])]]
    assert own and all(r["truth"] == "1" for r in own)
    assert [r for r in own if r["status"] == "deleted"] == []


def test_online_kept_at_an_earlier_step_is_what_that_step_kept():
    from pipeline.runs.online import OnlineConfig, run_online_steps

    seen = []
    config = OnlineConfig(formation="ring", robots=3, graph="ring", size=(192, 144),
                          max_features=150, steps=2, window=2, fusion=False, rerun=False)
    run = run_online_steps(config, batch_steps={0},
                           on_step=lambda r: seen.append(r["links_total"]))
    oa = run.online
    first = run.online_kept_at(0)
    assert len(first) == seen[0] == len(run.batch_kept[0])
    # what step 0 kept: cut at step 0 is out, cut later is still in
    L = oa.links
    assert first.tolist() == (L.step_cut[:seen[0]] != 0).tolist()
    assert run.online_kept_at(1).tolist() == L.kept.tolist()


def test_switching_topology_draws_the_graph_of_each_step(tmp_path, run_dir):
    out = tmp_path / "r"
    assert main(["run-formation", "--steps", "3", "--window", "2", "--switching-topology",
                 "--no-fusion", "--no-rerun", "--out", str(out), *FAST]) == 0
    report = json.loads((out / "report.json").read_text())
    full = json.loads((run_dir / "report.json").read_text())
    assert report["config"]["switching"] is True and report["conflict_free_every_step"]
    # the same frames, matched only along the edges up at each step
    pairs = [s["pairs_matched"] for s in report["steps"]]
    assert all(p <= q for p, q in zip(pairs, [s["pairs_matched"] for s in full["steps"]],
                                      strict=True))
    assert pairs != [s["pairs_matched"] for s in full["steps"]]
    # each step records the graph it used: a subset of the full one, not always all of it
    edges = {tuple(e) for e in full["comm_edges"]}
    per_step = [{tuple(e) for e in s["comm_edges"]} for s in report["steps"]]
    assert all(e <= edges for e in per_step) and any(e != edges for e in per_step)


def test_a_held_frame_costs_its_robot_its_keypoints_not_its_descriptors():
    from types import SimpleNamespace

    from pipeline.runs import online

    f = SimpleNamespace(keypoints=np.zeros((10, 2)))
    out = online._memory([f, f, f], [5120] * 3, np.array([0]), np.array([0, 0, 1]), 2,
                         keypoints_only=np.array([1, 2]))
    assert out.tolist() == [2 * 160 + 5120, 160]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 4), min_size=2, max_size=5), st.data())
def test_track_names_are_the_smallest_feature_id_of_each_set(counts, data):
    """Each feature's name is the smallest global id of its connected set of links (the
    name a robot's detection gives it), ``-1`` for a feature without a link: checked
    against scipy's connected components."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from pipeline.runs.online import track_names
    from pipeline.types import Links

    n, off = len(counts), np.concatenate([[0], np.cumsum(counts)])
    rows = data.draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, 3),
                                        st.integers(0, n - 1), st.integers(0, 3)), max_size=12))
    seen, keep = set(), []  # one-to-one per camera pair (Assumption 2.2)
    for a, r, b, s in sorted({(a, r % counts[a], b, s % counts[b]) for a, r, b, s in rows
                              if a < b}):
        if (a, r, b) not in seen and (b, s, a) not in seen:
            seen |= {(a, r, b), (b, s, a)}
            keep.append((a, r, b, s))
    rows = keep
    ci, fi, cj, fj = (np.array([x[k] for x in rows], np.int64) for k in range(4))
    names = track_names(counts, Links(ci, fi, cj, fj))
    ga, gb = off[ci] + fi, off[cj] + fj
    _, comp = connected_components(sp.coo_matrix((np.ones(len(ga)), (ga, gb)),
                                                 shape=(off[-1], off[-1])), directed=False)
    linked = np.zeros(off[-1], bool)
    linked[ga] = linked[gb] = True
    for g in range(off[-1]):
        want = min(np.flatnonzero(comp == comp[g])) if linked[g] else -1
        assert names[g] == want
