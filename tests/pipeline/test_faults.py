"""Fault flags: parsing, validation, network options and the report section."""

import argparse

import numpy as np
import pytest

from pipeline.consistency import resolve_conflicts
from pipeline.errors import InputError
from pipeline.faults import (
    FaultConfig,
    add_fault_arguments,
    fault_report,
    faults_from_args,
    parse_crash,
)
from pipeline.transport.simulated import Network, NetworkOptions
from pipeline.types import Links


def parse(argv):
    p = argparse.ArgumentParser()
    add_fault_arguments(p)
    return faults_from_args(p.parse_args(argv))


def test_defaults_are_fault_free():
    cfg = parse([])
    assert cfg == FaultConfig() and not cfg.any
    assert cfg.network_options([[0, 1]], 2) is None


def test_flags_parse():
    cfg = parse(["--drop-prob", "0.3", "--crash", "2@15", "--crash", " 0 @ 4 ",
                 "--switching-topology", "--fault-seed", "7"])
    assert cfg.drop_prob == 0.3 and cfg.crash == ((2, 15), (0, 4))
    assert cfg.switching_topology and cfg.seed == 7 and cfg.any
    opts = cfg.network_options([[0, 1], [1, 2]], 3)
    assert opts.drop_probability == 0.3 and opts.crash_at == {2: 15, 0: 4} and opts.seed == 7
    edges = np.asarray(opts.topology(0))
    assert edges.ndim == 2 and edges.shape[1] == 2
    assert cfg.as_dict()["crash"] == ["2@15", "0@4"]


@pytest.mark.parametrize("argv", [["--fault-seed", "7"], ["--fault-seed", "7", "--crash", "1@3"],
                                  ["--fault-seed", "7", "--delay-rounds", "2"]])
def test_a_fault_seed_with_nothing_random_to_seed_is_refused(argv):
    """--fault-seed seeds only the drops and the switching topology: without them it was
    accepted and changed nothing (resolve --crash 3@5 gave one output for every seed)."""
    with pytest.raises(InputError, match="--fault-seed 7: it seeds the message drops"):
        parse(argv)


def test_a_fault_seed_with_drops_or_switching_is_taken():
    assert parse(["--fault-seed", "7", "--drop-prob", "0.1"]).seed == 7
    assert parse(["--fault-seed", "7", "--switching-topology"]).seed == 7


@pytest.mark.parametrize("text", ["2", "2@", "@3", "a@3", "2@x", "-1@3", "2@-3", "2@3@4",
                                  "2.5@3", "", "2 3"])
def test_bad_crash_syntax_is_an_input_error(text):
    with pytest.raises(InputError, match="ROBOT@ROUND"):
        parse_crash(text)


@pytest.mark.parametrize("argv, match", [
    (["--drop-prob", "1"], "must be in"), (["--drop-prob", "-0.1"], "must be in"),
    (["--drop-prob", "half"], "not a number"), (["--drop-prob", "nan"], "must be in"),
    (["--crash", "1@2", "--crash", "1@5"], "more than once"),
    (["--fault-seed", "x"], "not an integer"),
])
def test_bad_values_are_input_errors(argv, match):
    with pytest.raises(InputError, match=match):
        parse(argv)


def test_crash_of_an_unknown_robot_names_it():
    cfg = parse(["--crash", "9@3"])
    with pytest.raises(InputError, match=r"robot 9 does not exist; robots are 0\.\.3"):
        cfg.network_options([[0, 1]], 4)
    with pytest.raises(InputError, match="robot 9 does not exist; the input has no robot"):
        cfg.network_options(np.zeros((0, 2), int), 0)  # not "robots are 0..-1"


def test_report_section_records_injection_and_effect():
    links = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0])  # paper Fig. 1
    cfg = FaultConfig(drop_prob=0.2, crash=((3, 2),), seed=1)
    res = resolve_conflicts([1, 1, 1, 2], None, links, cfg.network_options([[0, 1]], 4),
                            resolution="paper")
    base = resolve_conflicts([1, 1, 1, 2], None, links, resolution="paper")
    rep = fault_report(cfg, res, base)
    assert rep["injected"]["crash"] == ["3@2"] and rep["protocol"] == "reliable"
    assert rep["crashed"] == {"3": 2} and rep["robots_lost"] == {"3": [0, 2]}
    assert rep["links_cut_robot_lost"] == 2
    assert rep["extra_rounds"] > 0 and rep["extra_messages"] > 0
    assert rep["extra_rounds"] == rep["rounds"] - rep["fault_free_rounds"]


def _planted_rig():
    """4 cameras observing 30 points, complete comm graph; camera 2's keypoint of point 7 is
    40 px off (wrong but consistent): fusion must cut it, on a switching topology too."""
    from pipeline.types import Features, View

    rng = np.random.default_rng(3)
    n, P = 4, 30
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    pts = rng.uniform([-1, -1, 4], [1, 1, 7], (P, 3))
    views, feats = [], []
    for v in range(n):
        c = np.array([0.8 * v - 1.2, 0.1 * v, 0.0])
        z = np.array([0.0, 0.0, 5.0]) - c
        z /= np.linalg.norm(z)
        x = np.cross([0.0, -1.0, 0.0], z)
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(z, x), z])
        t = -R @ c
        p = (K @ (pts @ R.T + t).T).T
        uv = p[:, :2] / p[:, 2:] + rng.normal(0, 0.3, (P, 2))
        if v == 2:
            uv[7] += [40.0, 0.0]
        views.append(View(f"cam{v}", np.zeros((240, 320), np.uint8), K, R, t))
        feats.append(Features(uv.astype(np.float32), np.zeros((P, 4), np.float32),
                              np.ones(P, np.float32), "sift"))
    edges = np.array([(a, b) for a in range(n) for b in range(a + 1, n)])
    ci, cj = np.repeat(edges[:, 0], P), np.repeat(edges[:, 1], P)
    f = np.tile(np.arange(P), len(edges))
    return views, feats, Links(ci, f, cj, f), edges


def test_fusion_on_a_switching_topology_cuts_what_the_fixed_one_cuts():
    from pipeline.fusion.landmarks import fuse_tracks

    views, feats, links, edges = _planted_rig()
    fixed = fuse_tracks(views, feats, links, edges, sigma_px=0.5)
    topo = FaultConfig(switching_topology=True, seed=2).topology(edges)
    # the graph of a round is often disconnected; over 4 rounds every edge has been up
    assert any(len(topo(t)) < len(edges) for t in range(10))
    net = Network(len(views), edges, NetworkOptions(topology=topo))
    switching = fuse_tracks(views, feats, links, edges, sigma_px=0.5, transport=net)
    planted = ((links.cam_i == 2) | (links.cam_j == 2)) & (links.feat_i == 7)
    assert fixed.cut_links[planted].all() and not fixed.cut_links[~planted].any()
    np.testing.assert_array_equal(switching.cut_links, fixed.cut_links)
    # lockstep over the reliable channel: the same logical rounds, more network rounds
    assert switching.stats["rounds"] == fixed.stats["rounds"]
    assert switching.stats["network_rounds"] > fixed.stats["network_rounds"]
    np.testing.assert_array_equal(switching.points, fixed.points)


def test_resolve_command_records_faults(tmp_path, capsys):
    import json

    from pipeline.__main__ import main

    src = tmp_path / "in.csv"
    src.write_text("0,0,3,1\n0,0,1,0\n1,0,2,0\n2,0,3,0\n")  # paper Fig. 1
    out, rep = tmp_path / "out.csv", tmp_path / "rep.json"
    rc = main(["resolve", "--links", str(src), "--out", str(out), "--report", str(rep),
               "--drop-prob", "0.3", "--crash", "3@2", "--switching-topology"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "links cut robot-lost" in printed and "crashed: robot 3 at round 2" in printed
    assert "rounds" in printed and "vs the same rule fault-free" in printed and "+-" not in printed
    rows = out.read_text().splitlines()[1:]
    assert [r.split(",")[5] for r in rows] == ["robot-lost", "", "", "robot-lost"]
    f = json.loads(rep.read_text())["faults"]
    assert f["injected"] == {"drop_prob": 0.3, "delay_rounds": 0, "crash": ["3@2"],
                             "switching_topology": True,
                             "switch_p_up": 0.5, "switch_window": 4, "seed": 0}
    assert f["crashed"] == {"3": 2} and f["links_cut_robot_lost"] == 2
    assert f["extra_rounds"] > 0 and f["messages_dropped"] > 0
    # compared with the rule that ran (the default is not fault-tolerant: Alg. 1 ran), run
    # fault-free on the same input
    assert f["fault_free_resolution"] == "paper"
    ref = tmp_path / "ref.csv"
    assert main(["resolve", "--links", str(src), "--out", str(ref), "--resolution", "paper"]) == 0
    printed = capsys.readouterr().out
    cut_ref = sum(r.split(",")[4] == "deleted" for r in ref.read_text().splitlines()[1:])
    cut = sum(r.split(",")[4] == "deleted" for r in rows)
    assert f["extra_links_deleted"] == cut - cut_ref
    assert "crashed: robot 3 at round 2" not in printed  # the reference run has no faults


def test_run_formation_report_has_a_faults_section(tmp_path):
    import json

    from pipeline.__main__ import main

    out = tmp_path / "run"
    rc = main(["run-formation", "--formation", "a", "--size", "320x240", "--max-features", "300",
               "--no-rerun", "--drop-prob", "0.2", "--crash", "1@3", "--switching-topology",
               "--out", str(out)])
    assert rc == 0
    report = json.loads((out / "report.json").read_text())
    f = report["faults"]
    assert f["injected"]["crash"] == ["1@3"] and f["crashed"] == {"1": 3}
    assert f["links_cut_robot_lost"] > 0 and f["retransmissions"] > 0
    assert f["extra_rounds"] > 0 and f["extra_messages"] > 0
    assert report["after"]["conflictive_sets"] == 0
    links = (out / "links.csv").read_text().splitlines()
    cut = [r for r in links[1:] if r.split(",")[5] == "robot-lost"]
    assert len(cut) == f["links_cut_robot_lost"]
    assert all("1" in (r.split(",")[0], r.split(",")[2]) for r in cut)


def test_every_robot_crashed_before_fusion_is_said_not_a_traceback(tmp_path):
    """No robot is left to fuse: the run still writes its folder and says fusion did not run
    (exit 3 if conflicts remain, as any run that does not end conflict-free)."""
    import json

    from pipeline.__main__ import main

    out = tmp_path / "run"
    crash = [a for i in range(6) for a in ("--crash", f"{i}@0")]
    rc = main(["run-formation", "--formation", "c", "--size", "192x144", "--max-features",
               "150", "--no-rerun", *crash, "--out", str(out)])
    report = json.loads((out / "report.json").read_text())
    assert rc == (3 if report["after"]["conflictive_sets"] else 0)
    fusion = report["fusion"]
    assert fusion["enabled"] is False and fusion["reason"] == "every robot crashed before fusion"
    assert fusion["crashed_before_fusion"] == [0, 1, 2, 3, 4, 5]


def _formation_run(tmp_path, name, *crash):
    import csv
    import json

    from pipeline.__main__ import main

    out = tmp_path / name
    rc = main(["run-formation", "--formation", "a", "--size", "320x240", "--max-features", "300",
               "--no-rerun", "-q", "--out", str(out), *[a for c in crash for a in ("--crash", c)]])
    report = json.loads((out / "report.json").read_text())
    with open(out / "links.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    # every link matching produced comes back exactly once, every cut with a reason
    keys = [(r["cam_i"], r["feat_i"], r["cam_j"], r["feat_j"]) for r in rows]
    assert len(keys) == len(set(keys)) == report["before"]["links"]
    assert all((r["status"] == "deleted") == bool(r["reason"]) for r in rows)
    return rc, report, rows


def test_run_formation_crashes_before_and_during_fusion(tmp_path, capsys):
    """A robot crashed during consistency takes no part in fusion; one crashed during the
    fusion flood is listed in the fusion section and its links are not cut by fusion."""
    def touches(rows, robot):
        return [r for r in rows if str(robot) in (r["cam_i"], r["cam_j"])]

    # during consistency
    rc, report, rows = _formation_run(tmp_path, "early", "2@5")
    fs = report["fusion"]
    assert rc == 0 and report.get("conflict_free", True) and report["after"]["conflictive_sets"] == 0
    assert report["faults"]["crashed"] == {"2": 5}
    assert fs["crashed_before_fusion"] == [2] and fs["crashed"] == [] and fs["settled"]
    assert not any(r["reason"] == "fusion-outlier" for r in touches(rows, 2))
    assert "2" not in fs["robots_lost"] and not any(2 in v for v in fs["robots_lost"].values())

    # the consistency stage's rounds on this input, then a crash just after them
    _, probe, _ = _formation_run(tmp_path, "probe", "3@100000")
    start = probe["faults"]["rounds"]
    assert probe["fusion"]["crashed"] == [] and probe["faults"]["crashes_not_reached"]
    rc, report, rows = _formation_run(tmp_path, "late", f"3@{start + 1}")
    fs, f = report["fusion"], report["faults"]
    assert rc == 0 and report["after"]["conflictive_sets"] == 0
    assert f["crashed"] == {} and f["crashes_not_reached"] == {}
    assert f["crashed_during_fusion"] == {"3": start + 1}
    assert fs["crashed"] == [3] and fs["crashed_before_fusion"] == [] and fs["settled"]
    assert sorted(fs["robots_lost"]) and all(v == [3] for v in fs["robots_lost"].values())
    assert fs["network_rounds"] > probe["fusion"]["network_rounds"]
    assert not any(r["reason"] == "fusion-outlier" for r in touches(rows, 3))
    # the robots that did not crash judged the rest: fusion still cut links among them
    assert fs["links_cut"] > 0
    # no warning but the one that the default rule gives way to Alg. 1 under --crash, and the
    # robot lost during the consistency stage (the early run's robot 2), named once
    warned = [ln for ln in capsys.readouterr().err.lower().splitlines() if "warning" in ln]
    lost = [ln for ln in warned if "robot(s) 2 crashed" in ln]
    assert len(lost) == 1 and "link(s) to them were cut as robot-lost" in lost[0]
    assert all("is not fault-tolerant: with --crash" in ln for ln in warned if ln not in lost), \
        warned


@pytest.mark.parametrize("flags", [["--crash", "1@2"], ["--delay-rounds", "2"],
                                   ["--switching-topology"]])
def test_a_simulated_fault_over_zenoh_is_refused_before_any_warning(tmp_path, capsys, flags):
    """It was warned that the rule gives way to Alg. 1 under the fault, then refused."""
    from pipeline.__main__ import main

    links = tmp_path / "l.csv"
    links.write_text("0,0,1,0\n1,0,2,0\n2,0,0,1\n")
    rc = main(["resolve", "--links", str(links), "--out", str(tmp_path / "o.csv"),
               "--transport", "zenoh", *flags])
    err = capsys.readouterr().err
    assert rc == 2 and "faults of the simulated network" in err
    assert "not fault-tolerant" not in err
    assert not (tmp_path / "o.csv").exists()


def test_run_formation_refuses_a_simulated_fault_over_zenoh_before_any_warning(tmp_path, capsys):
    from pipeline.__main__ import main

    rc = main(["run-formation", "--transport", "zenoh", "--crash", "1@2", "--no-rerun",
               "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert rc == 2 and "faults of the simulated network" in err
    assert "not fault-tolerant" not in err and not (tmp_path / "run").exists()


def test_the_work_check_counts_the_association_graphs_diameter():
    """Detection stops d + 1 logical rounds in with d the association graph's diameter
    (Cor. 3.6), not the comm graph's: three fully connected cameras and a chain of 7,000
    links at --delay-rounds 100 are some 2.1 million robot-rounds, refused before the run."""
    from pipeline.faults import check_simulated_work
    L = 7000
    k = np.arange(L + 1)
    cam = k % 3
    feat = k // 3
    a, b = np.stack([cam[:-1], feat[:-1]], 1), np.stack([cam[1:], feat[1:]], 1)
    swap = a[:, 0] > b[:, 0]
    a[swap], b[swap] = b[swap], a[swap].copy()
    links = Links(a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    fpc = np.bincount(cam, minlength=3)
    tri = np.array([[0, 1], [0, 2], [1, 2]])
    faults = FaultConfig(delay_rounds=100)
    check_simulated_work(3, tri, faults)  # the comm graph alone: 1,212 robot-rounds
    with pytest.raises(InputError, match=r"association graph \(links\) of diameter 7000"):
        check_simulated_work(3, tri, faults, fpc, links)


@pytest.mark.parametrize("fields, needle", [
    (dict(drop_prob="0.1"), r"FaultConfig drop_prob '0\.1': give a probability"),
    (dict(crash=((1.5, 2),)), r"FaultConfig crash \(1\.5, 2\): give \(robot, round\) pairs"),
    (dict(crash=((1,),)), r"FaultConfig crash \(1,\)"),
    (dict(crash=((1, -5),)), r"FaultConfig crash \(1, -5\)"),
    (dict(switching_topology="no"), r"FaultConfig switching_topology 'no': give True or False"),
    (dict(seed=-1), r"FaultConfig seed -1: a seed must be an integer from 0"),
    (dict(seed=1.5), r"FaultConfig seed 1\.5"),
])
def test_fault_config_names_a_field_of_the_wrong_type(fields, needle):
    """'0.1' failed in float(), a crash of robot 1.5 crashed robot 1, 'no' switched the
    topology on, a negative seed was taken."""
    with pytest.raises(InputError, match=needle):
        FaultConfig(**fields)
    assert FaultConfig(crash=((np.int64(1), 4),), switching_topology=np.bool_(True)).any
