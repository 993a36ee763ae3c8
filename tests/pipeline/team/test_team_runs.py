"""Robots as processes over Zenoh: same links as the simulator, real faults, bad inputs.

Small inputs (a 6-robot formation at 160x120, online steps of 4 robots, a 4-robot links file)
keep each case to a few seconds of process start-up.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.consistency.centralized import is_conflict_free
from pipeline.runs.formation import FormationConfig, run_formation
from pipeline.types import Links

SMALL = dict(seed=0, size=(160, 120), fusion=False, rerun=False)


@pytest.fixture(autouse=True)
def _scene_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


@pytest.fixture(scope="module")
def links_input(tmp_path_factory):
    """A 4-camera links file with conflictive sets and a quality per link, and its complete
    comm graph."""
    rng = np.random.default_rng(1)
    rows = set()
    for _ in range(120):
        i, j = sorted(rng.choice(4, 2, replace=False))
        rows.add((int(i), int(rng.integers(12)), int(j), int(rng.integers(12))))
    # one-to-one per camera pair
    seen, keep = set(), []
    for i, r, j, s in sorted(rows):
        if (i, r, j) in seen or (j, s, i) in seen:
            continue
        seen |= {(i, r, j), (j, s, i)}
        keep.append((i, r, j, s))
    d = tmp_path_factory.mktemp("links")
    # a quality (1 - Lowe ratio) per link: the evidence of the evidence rule
    quality = rng.uniform(0.05, 0.95, len(keep)).round(3)
    (d / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j,quality\n" + "".join(
        f"{i},{r},{j},{s},{q}\n" for (i, r, j, s), q in zip(keep, quality, strict=True)))
    (d / "graph.csv").write_text("".join(f"{i},{j}\n" for i in range(4) for j in range(i + 1, 4)))
    return d


def _rows(path):
    """Every row's link, status and reason (the round column may differ: the zenoh team
    counts its rounds with the termination wave's)."""
    return [tuple(line.split(",")[:6]) for line in Path(path).read_text().splitlines()]


@pytest.mark.parametrize("formation,resolution,fusion", [
    ("a", "evidence", True), ("b", "evidence", False), ("c", "evidence", False),
    ("d", "evidence", True), ("d", "paper", False)])
def test_zenoh_links_equal_the_simulators_formation(formation, resolution, fusion, tmp_path):
    sim, zen = tmp_path / "sim", tmp_path / "zenoh"
    cfg = dict(formation=formation, resolution=resolution, **{**SMALL, "fusion": fusion})
    run_formation(FormationConfig(out=str(sim), **cfg))
    run_formation(FormationConfig(out=str(zen), **cfg), transport="zenoh")
    sim_rows = _rows(sim / "links.csv")
    assert _rows(zen / "links.csv") == sim_rows
    assert any(r[4] == "deleted" for r in sim_rows[1:])  # the formation had conflicts to cut
    report = json.loads((zen / "report.json").read_text())
    if fusion:  # the robots' own fusion cut what the simulator's cut, in as many rounds
        assert any(r[5] == "fusion-outlier" for r in sim_rows[1:])
        sim_fusion = json.loads((sim / "report.json").read_text())["fusion"]
        assert report["fusion"]["rounds"] == sim_fusion["rounds"]
        assert report["fusion"]["settled"] is sim_fusion["settled"] is True
        assert report["fusion"]["fused_points"] == sim_fusion["fused_points"]
        # every message a robot sent counted once, at its size: its cut notices too
        assert report["fusion"]["bytes_by_kind"] == sim_fusion["bytes_by_kind"]
        # the fused landmarks are judged alike (same tracks, same features' truth), to
        # within the rounding of the robots' float32 wire
        for key in ("median_error_vs_ground_truth", "p90_error_vs_ground_truth",
                    "median_pycolmap_error_vs_ground_truth", "median_distance_to_pycolmap"):
            assert report["fusion"][key] == pytest.approx(sim_fusion[key], rel=1e-4, abs=1e-6)
        # every other figure of the simulator's stage is the robots' alike (tracks and
        # observations from the names they started from, votes, options, per-robot noise,
        # messages and bytes); left out: how the messages were carried (each robot counts its
        # own network rounds), which the two transports count differently
        carried = {"network_rounds", "gate_cycles", "dropped", "crashed"}
        for key, value in sim_fusion.items():
            if key in carried:
                continue
            assert key in report["fusion"], key
            if isinstance(value, float):
                assert report["fusion"][key] == pytest.approx(value, rel=1e-4, abs=1e-6), key
            else:
                assert report["fusion"][key] == value, key
    assert report["resolution"]["method"] == resolution
    assert report["team"]["transport"] == "zenoh"
    # every stage's wire bytes add up to the robot's
    has_lower = {max(e) for e in report["comm_edges"]}
    for i, r in report["team"]["robots"].items():
        stages = r["wire_bytes_by_stage"]
        assert list(stages) == ["exchange", "consistency"] + (["fusion"] if fusion else [])
        assert all(v > 0 for v in stages.values()) and sum(stages.values()) == r["wire_bytes"]
        # features go only to the neighbour that matches with them (the lower id)
        assert (r["bytes_by_kind"].get("features", 0) > 0) == (int(i) in has_lower)


@pytest.mark.parametrize("resolution", ["evidence", "paper", "sync"])
def test_zenoh_links_equal_the_simulators_resolve(links_input, tmp_path, resolution):
    args = ["resolve", "--links", str(links_input / "in.csv"), "--comm-graph",
            str(links_input / "graph.csv"), "--resolution", resolution]
    assert main([*args, "--out", str(tmp_path / "sim.csv"),
                 "--report", str(tmp_path / "sim.json")]) == 0
    assert main([*args, "--out", str(tmp_path / "zen.csv"), "--transport", "zenoh",
                 "--report", str(tmp_path / "zen.json")]) == 0
    sim = _rows(tmp_path / "sim.csv")
    assert _rows(tmp_path / "zen.csv") == sim
    assert sum(r[4] == "deleted" for r in sim[1:]) > 0  # the input had conflicts to cut
    zen = json.loads((tmp_path / "zen.json").read_text())
    assert zen["resolution_method"] == resolution
    if resolution in ("sync", "evidence"):  # one pass: as the simulator counts it (sync's
        # robots counted their Borůvka rounds)
        sim_report = json.loads((tmp_path / "sim.json").read_text())
        assert zen["resolution"]["iterations"] == sim_report["resolution"]["iterations"]


@pytest.mark.parametrize("resolution", ["sync", "evidence"])
def test_zenoh_robots_decide_on_the_link_weights_given_them(links_input, resolution):
    """The weights of the links (clean-db's Sampson evidence, not the links file's quality)
    reach each robot process in its own weights file (data.weights): the robots decide as
    the simulator given the same weights, and not as on the quality alone."""
    from pipeline.inputs.linkscsv import read_links_csv
    from pipeline.runs.transports import sim, zenoh

    links = read_links_csv(links_input / "in.csv").links
    m = np.full(4, 12)
    edges = np.array([[i, j] for i in range(4) for j in range(i + 1, 4)])
    w = np.random.default_rng(5).normal(0.0, 3.0, len(links))
    evidence = {"link_weight": w, "keypoints": None}
    on_quality, _ = sim.resolve(m, edges, links, None, resolution, None)
    given, _ = sim.resolve(m, edges, links, None, resolution, None, evidence=evidence)
    assert (on_quality.deleted != given.deleted).any()  # the weights decide here
    robots, _ = zenoh.resolve(m, edges, links, None, resolution, None, evidence=evidence)
    np.testing.assert_array_equal(robots.deleted, given.deleted)


@pytest.mark.parametrize("resolution", ["sync", "paper"])
def test_zenoh_robots_decide_on_links_of_quality_minus_inf(links_input, resolution):
    """run-landmarks' assignment gives a pair whose nearest alternative is at distance 0 the
    ratio inf, quality -inf (the 101 CMU hotel frames, ring2): the simulator takes it (weight
    -inf), and the robots, which had it in their links files, refused them ("quality '-inf'
    is not a finite number") and stopped the run; they now decide as the simulator."""
    from pipeline.inputs.linkscsv import read_links_csv
    from pipeline.runs.transports import sim, zenoh

    links = read_links_csv(links_input / "in.csv").links
    links.quality[::5] = -np.inf
    m = np.full(4, 12)
    edges = np.array([[i, j] for i in range(4) for j in range(i + 1, 4)])
    simulated, _ = sim.resolve(m, edges, links, None, resolution, None)
    robots, _ = zenoh.resolve(m, edges, links, None, resolution, None)
    assert simulated.deleted.any()
    np.testing.assert_array_equal(robots.deleted, simulated.deleted)


def test_zenoh_links_equal_the_simulators_clean_db(tmp_path):
    """clean-db --transport zenoh: one robot process per image, each with its own rows, their
    weights (the pair's stored geometry) and its keypoints; the same OUT.links.csv as the
    simulator's, and --fusion (a mapping of the whole database) is refused over zenoh."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "commands"))
    from test_clean_db import _db_with_planted_conflicts

    src = tmp_path / "in.db"
    _db_with_planted_conflicts(src)
    for rule in ("sync", "evidence"):
        for t in ("sim", "zenoh"):
            assert main(["clean-db", str(src), "--out", str(tmp_path / f"{rule}-{t}.db"),
                         "--resolution", rule, "--transport", t, "--no-rerun",
                         "--report", str(tmp_path / f"{rule}-{t}.json")]) == 0
        sim = _rows(tmp_path / f"{rule}-sim.links.csv")
        assert _rows(tmp_path / f"{rule}-zenoh.links.csv") == sim
        assert sum(r[5] == "resolution" for r in sim[1:]) > 0
        rep = json.loads((tmp_path / f"{rule}-zenoh.json").read_text())
        assert rep["resolution"]["transport"] == "zenoh" and len(rep["resolution"]["team"]["robots"]) == 4
    assert main(["clean-db", str(src), "--out", str(tmp_path / "f.db"), "--fusion",
                 "--transport", "zenoh"]) == 2
    assert not (tmp_path / "f.db").exists()


@pytest.mark.parametrize("resolution", ["sync", "paper"])
def test_zenoh_links_equal_the_simulators_clean_h5(tmp_path, resolution):
    """clean-h5 --transport zenoh (three images, one Fig. 1 conflict): one robot process per
    image, the same OUT.links.csv as the simulator's for the rule given."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "commands"))
    from test_clean_h5 import _write

    feats, matches = _write(tmp_path)
    for t in ("sim", "zenoh"):
        assert main(["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
                     str(tmp_path / f"{t}.h5"), "--resolution", resolution, "--transport", t,
                     "--no-rerun", "--report", str(tmp_path / f"{t}.json")]) == 0
    sim = _rows(tmp_path / "sim.links.csv")
    assert _rows(tmp_path / "zenoh.links.csv") == sim
    assert sum(r[5] == "resolution" for r in sim[1:]) > 0
    rep = json.loads((tmp_path / "zenoh.json").read_text())
    assert rep["resolution"]["resolution"] == resolution
    assert rep["resolution"]["transport"] == "zenoh" and len(rep["resolution"]["team"]["robots"]) == 3


@pytest.mark.parametrize("command", ["clean-db", "clean-h5", "run-landmarks"])
def test_a_robot_lost_while_cleaning_writes_nothing(tmp_path, monkeypatch, capsys, command):
    """A robot process killed during clean-db's or clean-h5's stage: its links came back as
    cut (reason 'resolution') and left the cleaned file, though nothing judged them; in
    run-landmarks they lowered the scores as the rule's cuts. Now the command stops, naming
    the image, and writes nothing."""
    import pipeline.runs.transports.zenoh as zen

    original = zen.resolve_links_file

    def killing(*a, **k):
        return original(*a, **{**k, "kill": (1, "consistency", 0.0)})

    monkeypatch.setattr(zen, "resolve_links_file", killing)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "commands"))
    if command == "clean-db":
        from test_clean_db import _db_with_planted_conflicts

        _db_with_planted_conflicts(tmp_path / "in.db")
        args = ["clean-db", str(tmp_path / "in.db"), "--out", str(tmp_path / "out.db")]
        name = "view_1.jpg"
    elif command == "clean-h5":
        from test_clean_h5 import _write

        feats, matches = _write(tmp_path)
        args = ["clean-h5", "--features", str(feats), "--matches", str(matches), "--out",
                str(tmp_path / "out.h5")]
        name = "c.jpg"  # the second name in sorted order
    else:
        hotel = Path(__file__).resolve().parents[2] / "data" / "cmu_hotel_small"
        args = ["run-landmarks", str(hotel), "--geometry", "none", "--no-baselines", "--out",
                str(tmp_path / "out")]
        name = "hotel.seq20.png"  # the second image in natural name order
    rerun = [] if command == "run-landmarks" else ["--no-rerun"]  # it writes no recording
    assert main([*args, "--transport", "zenoh", *rerun]) != 0
    err = capsys.readouterr().err
    assert f"the robot process of image {name!r} was lost during {command}" in err
    assert not list(tmp_path.glob("out*"))


def _kept_links(path):
    rows = [r.split(",") for r in Path(path).read_text().splitlines()[1:]]
    kept = [r for r in rows if r[4] == "kept"]
    return Links([int(r[0]) for r in kept], [int(r[1]) for r in kept],
                 [int(r[2]) for r in kept], [int(r[3]) for r in kept]), rows


def test_kill_9_of_one_robot_survivors_finish_conflict_free(tmp_path):
    runs = []
    cfg = FormationConfig(formation="complete", robots=4, graph="complete",
                          out=str(tmp_path / "run"), **SMALL)
    out = run_formation(cfg, transport="zenoh", kill=(2, "consistency", 0.0), keep_run=runs,
                             round_timeout_s=1.0)
    run = runs[0]
    assert 2 in run.killed and 2 not in run.results
    assert sorted(run.results) == [0, 1, 3]
    # bounded: the survivors finished within the round timeout plus T silent rounds
    assert all(t - run.killed[2] < 30 for t in run.finished_at.values())
    report = json.loads((out / "report.json").read_text())
    assert report["faults"]["robots_lost"] == {"2": [0, 1, 3]}
    assert report["faults"]["links_cut_robot_lost"] > 0
    kept, rows = _kept_links(out / "links.csv")
    assert all(r[5] == "robot-lost" or r[4] == "kept" or r[5] == "resolution" for r in rows)
    assert not any(r[4] == "kept" and "2" in (r[0], r[2]) for r in rows)
    m = report["features_per_camera"]
    assert is_conflict_free(m, kept) and report["after"]["conflictive_sets"] == 0


def test_kill_9_of_one_robot_during_fusion(tmp_path):
    runs = []
    cfg = FormationConfig(formation="complete", robots=4, graph="complete",
                          out=str(tmp_path / "run"), **{**SMALL, "fusion": True})
    out = run_formation(cfg, transport="zenoh", kill=(2, "fusion", 0.0), keep_run=runs, round_timeout_s=1.0)
    run = runs[0]
    assert 2 in run.killed and sorted(run.results) == [0, 1, 3]
    assert all(t - run.killed[2] < 30 for t in run.finished_at.values())
    report = json.loads((out / "report.json").read_text())
    assert report["fusion"]["enabled"] and report["fusion"]["robots_lost"]
    # per-robot figures by robot id: the killed robot published none
    sigma = report["fusion"]["robot_sigma_px"]
    assert len(sigma) == 4 and sigma[2] is None and None not in sigma[:2] + sigma[3:]
    kept, rows = _kept_links(out / "links.csv")
    touching = [r for r in rows if "2" in (r[0], r[2])]
    assert touching and all(r[4] == "deleted" for r in touching)
    assert any(r[5] == "robot-lost" for r in touching)
    m = report["features_per_camera"]
    assert is_conflict_free(m, kept) and report["after"]["conflictive_sets"] == 0


def test_message_loss_at_the_zenoh_transport_is_handled(links_input, tmp_path):
    rep = tmp_path / "r.json"
    assert main(["resolve", "--links", str(links_input / "in.csv"), "--out",
                 str(tmp_path / "z.csv"), "--transport", "zenoh", "--drop-prob", "0.3",
                 "--report", str(rep)]) == 0
    s = json.loads(rep.read_text())
    # as in the simulator, a lossy network runs the fault-tolerant Alg. 1
    assert s["resolution_method"] == "paper"
    assert s["faults"]["messages_dropped"] > 0 and s["faults"]["retransmissions"] > 0
    assert s["faults"]["links_cut_robot_lost"] == 0  # nothing lost, only delayed
    assert s["after"]["conflictive_sets"] == 0


def test_message_loss_during_fusion_over_zenoh_is_handled(tmp_path):
    from pipeline.faults import FaultConfig

    cfg = FormationConfig(formation="complete", robots=4, graph="complete",
                          out=str(tmp_path / "run"), faults=FaultConfig(drop_prob=0.2, seed=3),
                          **{**SMALL, "fusion": True})
    out = run_formation(cfg, transport="zenoh")
    report = json.loads((out / "report.json").read_text())
    fusion = report["fusion"]
    # the fusion rounds went over the reliable channel: losses were retransmitted
    assert fusion["enabled"] and fusion["retransmissions"] > 0 and not fusion["robots_lost"]
    assert fusion["cut_links"] > 0 and report["faults"]["links_cut_robot_lost"] == 0
    kept, _ = _kept_links(out / "links.csv")
    assert is_conflict_free(report["features_per_camera"], kept)


def _team_file(tmp_path, ports, links_input, **opts):
    doc = {"name": "t", "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{p}"}
                                   for i, p in enumerate(ports)],
           "comm_edges": [[0, 1]],
           "data": {"kind": "links", "links": str(links_input / "two.csv"),
                    "features_per_camera": [3, 3]},
           "options": opts}
    (links_input / "two.csv").write_text("0,1,1,2\n")
    p = tmp_path / "TEAM.json"
    p.write_text(json.dumps(doc))
    return p


def _free_port():
    from pipeline.team.launcher import free_ports

    return free_ports(1)[0]


def test_robot_bad_inputs_are_one_line_errors(links_input, tmp_path, capsys):
    team = _team_file(tmp_path, [_free_port(), _free_port()], links_input)
    assert main(["robot", "--team", str(team), "--id", "5"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: --id 5: not a robot of team 't'; its robots are 0..1"
    bad = tmp_path / "bad.json"
    bad.write_text('{"robots": [}')
    assert main(["robot", "--team", str(bad), "--id", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: team file") and "not valid JSON" in err and "\n" not in err


def test_port_in_use_is_a_one_line_error(links_input, tmp_path, capsys):
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        team = _team_file(tmp_path, [busy.getsockname()[1], _free_port()], links_input)
        assert main(["robot", "--team", str(team), "--id", "0"]) == 2
    finally:
        busy.close()
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error: robot 0: cannot listen on tcp/127.0.0.1:")


def test_a_robot_that_never_starts_is_named(links_input, tmp_path, capsys):
    team = _team_file(tmp_path, [_free_port(), _free_port()], links_input, start_timeout_s=1.5)
    assert main(["robot", "--team", str(team), "--id", "0"]) == 3
    err = capsys.readouterr().err
    assert "neighbour robot 1 (tcp/127.0.0.1:" in err and "never started" in err


def _children(pid):
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True,
                         text=True).stdout.split()
    return [int(p) for p in out]


def _descendants(pid):
    kids = _children(pid)
    return kids + [g for k in kids for g in _children(k)]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL, "SIGINT twice"])
def test_interrupted_launcher_leaves_no_robot_behind(links_input, tmp_path, sig):
    """Ctrl-C, kill -9, and Ctrl-C twice (or the SIGINT `timeout` forwards after the one the
    process group got): every robot gone, and the launcher ends (a second SIGINT during its
    cleanup once left the observer's Zenoh session open and the process alive)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    # a full-size formation keeps the six robots busy for seconds
    proc = subprocess.Popen(
        [sys.executable, "-m", "pipeline", "run-formation", "--formation", "a", "--no-fusion",
         "--no-rerun", "--out", str(tmp_path / "run"), "--transport", "zenoh"], env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    kids = []
    t0 = time.monotonic()
    # the robots' zygote and the six robots it forked
    while len(kids) < 7 and time.monotonic() - t0 < 30:
        kids = _descendants(proc.pid)
        time.sleep(0.05)
    assert len(kids) == 7
    if sig == "SIGINT twice":
        proc.send_signal(signal.SIGINT)
        time.sleep(0.002)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 130
    else:
        proc.send_signal(sig)
        proc.wait(timeout=20)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 10 and any(os.path.exists(f"/proc/{k}") and
                                             "Z" not in _state(k) for k in kids):
        time.sleep(0.05)
    assert not [k for k in kids if os.path.exists(f"/proc/{k}") and "Z" not in _state(k)]


def _state(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2]
    except OSError:
        return "Z"


def test_a_robot_that_fails_is_named_by_the_launcher(tmp_path):
    from pipeline.errors import TeamError
    from pipeline.team.launcher import launch_team, make_team

    team = make_team("t", [[0, 1]], {"kind": "links", "links": str(tmp_path / "missing.csv"),
                                      "features_per_camera": [2, 2]}, n=2)
    with pytest.raises(TeamError, match=r"robot \d \(tcp/127\.0\.0\.1:\d+\) failed with exit "
                                        r"code 2: error: .*missing\.csv"):
        launch_team(team, tmp_path / "team", timeout_s=60)


def test_forked_and_separately_started_robots_give_the_same_result(links_input, tmp_path):
    from pipeline.team.launcher import launch_team, make_team

    fpc = [12, 12, 12, 12]
    data = {"kind": "links", "links": str(links_input / "in.csv"), "features_per_camera": fpc}
    edges = [[i, j] for i in range(4) for j in range(i + 1, 4)]
    runs = {fork: launch_team(make_team("f", edges, data, n=4), tmp_path / str(fork),
                              fork=fork, timeout_s=120) for fork in (True, False)}
    assert (tmp_path / "True" / "zygote.log").exists()
    assert not (tmp_path / "False" / "zygote.log").exists()
    for run in runs.values():
        assert sorted(run.results) == [0, 1, 2, 3] and set(run.exit_codes.values()) == {0}
    for i in range(4):
        a, b = runs[True].results[i][1], runs[False].results[i][1]
        for k in ("link_alive", "deleted_case", "deleted_round"):
            np.testing.assert_array_equal(a[k], b[k])


def test_zenoh_links_equal_the_simulators_run_images(sceaux_small, tmp_path):
    """Four photographs, photo defaults: each robot loads and extracts its own."""
    args = ["run-images", str(sceaux_small), "--graph", "complete", "--max-size", "320",
            "--no-fusion", "--no-rerun"]
    assert main([*args, "--out", str(tmp_path / "sim")]) == 0
    assert main([*args, "--out", str(tmp_path / "zen"), "--transport", "zenoh"]) == 0
    sim = Path(tmp_path / "sim" / "links.csv").read_text().splitlines()
    assert Path(tmp_path / "zen" / "links.csv").read_text().splitlines() == sim
    assert len(sim) > 500
    rep = json.loads((tmp_path / "zen" / "report.json").read_text())
    sim_rep = json.loads((tmp_path / "sim" / "report.json").read_text())
    assert rep["features_per_camera"] == sim_rep["features_per_camera"]
    assert rep["resolution"]["method"] == "evidence" and rep["team"]["transport"] == "zenoh"
    assert rep["fusion"]["enabled"] is False


@pytest.mark.parametrize("resolution, extra", [("sync", ["--geometry", "none"]),
                                               ("paper", [])])
def test_zenoh_links_equal_the_simulators_run_landmarks(tmp_path, resolution, extra):
    """Six labelled hotel frames: over zenoh the rule runs as one robot process per image,
    each reading its own rows of the matched links, and decides as the simulator."""
    hotel = Path(__file__).resolve().parents[2] / "data" / "cmu_hotel_small"
    args = ["run-landmarks", str(hotel), "--graph", "complete", "--resolution", resolution,
            "--no-baselines", *extra]
    assert main([*args, "--out", str(tmp_path / "sim")]) == 0
    assert main([*args, "--out", str(tmp_path / "zen"), "--transport", "zenoh"]) == 0
    sim = _rows(tmp_path / "sim" / "links.csv")
    assert _rows(tmp_path / "zen" / "links.csv") == sim
    rep = json.loads((tmp_path / "zen" / "report.json").read_text())
    sim_rep = json.loads((tmp_path / "sim" / "report.json").read_text())
    assert rep["resolution"]["transport"] == "zenoh" and sim_rep["resolution"]["transport"] == "sim"
    assert rep["pairwise"] == sim_rep["pairwise"] and rep["after"] == sim_rep["after"]
    assert len(rep["team"]["robots"]) == 6 and "team" not in sim_rep
    if resolution == "sync":  # the descriptor matches had conflicts for the rule to cut
        assert sum(r[4] == "deleted" for r in sim[1:]) > 0


def test_run_images_over_zenoh_with_a_similarity_graph_is_a_one_line_error(sceaux_small,
                                                                           tmp_path, capsys):
    assert main(["run-images", str(sceaux_small), "--graph", "knn:2", "--max-size", "320",
                 "--out", str(tmp_path / "z"), "--transport", "zenoh"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error: --graph knn:2: knn:K chooses neighbours from every image")
    assert not (tmp_path / "z").exists()


@pytest.mark.parametrize("resolution,fusion,n_steps", [
    ("evidence", True, 3), ("sync", False, 3), ("paper", True, 5)])
def test_zenoh_online_steps_equal_the_simulators(resolution, fusion, n_steps, tmp_path):
    """``run-formation --steps N --transport zenoh``: each step's stage runs as robot processes
    (one per frame of the step's sub-problem), and so does each step's fusion of the changed
    tracks (one per frame of those tracks); every link is made, kept and cut at the same step,
    for the same reason, as on the simulator, and each step fuses and cuts as much. Five steps
    of window 2 (hold 1): frames retire from step 4 on, and the robot processes run the
    history check on retired pieces. Four robots on a ring (a cycle, conflicts to cut) keep
    each team's start-up short: the paper's six took twice the CPU for the same checks."""
    args = ["run-formation", "--steps", str(n_steps), "--window", "2", "--size", "160x120",
            "--max-features", "120", "--robots", "4", "--graph", "ring", "--no-rerun",
            "--resolution", resolution] + ([] if fusion else ["--no-fusion"])
    assert main([*args, "--out", str(tmp_path / "sim")]) == 0
    assert main([*args, "--transport", "zenoh", "--out", str(tmp_path / "zen")]) == 0
    for name in ("links.csv", "link_steps.csv"):
        sim = Path(tmp_path / "sim" / name).read_text().splitlines()
        assert Path(tmp_path / "zen" / name).read_text().splitlines() == sim, name
    steps = json.loads((tmp_path / "sim" / "report.json").read_text())["steps"]
    assert sum(s["cut"] for s in steps) > 0  # the steps had conflicts to cut
    zen = json.loads((tmp_path / "zen" / "report.json").read_text())
    assert zen["config"]["transport"] == "zenoh"
    assert all(s["conflictive_sets_after"] == 0 for s in zen["steps"])
    # what each step acted on, counted alike (over zenoh it read one robot's phases, or none,
    # and went negative once the sets solved at their roots were taken off)
    counts = ("conflictive_features", "conflictive_sets", "cut", "cut_rule", "links_kept")
    assert [{k: s[k] for k in counts} for s in zen["steps"]] == \
        [{k: s[k] for k in counts} for s in steps]
    # the robots' own counts (the reliable protocol's acks and termination wave), not the
    # simulator's: the stage ran in the robot processes
    assert [s["messages"] for s in zen["steps"]] != [s["messages"] for s in steps]
    if len(steps) > 3:  # pieces retired: the robots' check examined sets that reach them
        assert sum(s["history_bytes"] for s in zen["steps"][3:]) > 0
    if fusion:
        # each step's fusion: the same cuts, tracks and rounds, and every message a robot
        # sent counted once, at its size (the notices of the robots' cuts too)
        keys = ("cut", "tracks", "rounds", "messages", "bytes")
        figures = [{k: s["fusion"][k] for k in keys} for s in steps]
        assert [{k: s["fusion"][k] for k in keys} for s in zen["steps"]] == figures
        assert all(f["tracks"] > 0 for f in figures)
        # the robots named their tracks themselves (a detection before the fusion)
        assert all(s["fusion"]["naming_rounds"] > 0 for s in zen["steps"])
        if resolution == "paper":  # Alg. 1 leaves spurious links that fusion votes out
            assert sum(f["cut"] for f in figures) > 0
            with open(tmp_path / "zen" / "links.csv") as f:
                assert any(",fusion-outlier," in line for line in f)


def test_zenoh_sequence_steps_equal_the_simulators(tmp_path):
    """``run-images DIR --sequence --transport zenoh``: photographs (no poses) of two robots,
    each step's stage as robot processes; the same links, steps and reasons as the simulator."""
    import shutil

    sceaux = Path(__file__).parents[2] / "data" / "sceaux_castle_640"
    files = sorted(sceaux.glob("*.JPG"))
    root = tmp_path / "team"
    for robot, idx in (("a", [0, 2, 4]), ("b", [1, 3, 5])):
        (root / robot).mkdir(parents=True)
        for k, i in enumerate(idx):
            shutil.copy(files[i], root / robot / f"{k}.jpg")
    shutil.copy(sceaux / "K.txt", root / "K.txt")
    args = ["run-images", str(root), "--sequence", "--window", "2", "--max-size", "200",
            "--features", "sift", "--max-features", "200", "--matcher", "opencv", "--graph",
            "complete", "--no-rerun"]
    assert main([*args, "--out", str(tmp_path / "sim")]) == 0
    assert main([*args, "--transport", "zenoh", "--out", str(tmp_path / "zen")]) == 0
    for name in ("links.csv", "link_steps.csv"):
        sim = Path(tmp_path / "sim" / name).read_text().splitlines()
        assert Path(tmp_path / "zen" / name).read_text().splitlines() == sim, name
    assert len(sim) > 100


def _two_tracks_joined_through_the_window(oa, weak: float):
    """Tracks A = {0:0, 1:0} and B = {0:1, 1:1} of step 0 retire as two pieces; B reaches
    the window through a link of quality ``weak``; at step 2 frame 4 joins both."""
    from pipeline.consistency.engines.online import Frame

    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [0, 1], [2, 3], [0, 0], [0.9, weak]))
    return oa.add_step([Frame(0, 1), Frame(1, 1)],
                       Links([2, 3, 4], [0, 0, 0], [4, 4, 5], [0, 0, 0], [0.8, 0.9, 0.7]))


@pytest.mark.parametrize("resolution,weak", [("paper", 0.2), ("evidence", 0.95)])
def test_zenoh_robots_run_the_history_check_as_the_record(resolution, weak):
    """An online step's history check (two retired pieces sharing a retired frame, joined
    through the window) run by the robot processes themselves after the rule: the same link
    cut, for the same reason, as the simulator's record computes; the robots' rounds and
    bytes of the check are reported."""
    from pipeline.consistency.engines.online import HISTORY, OnlineAssociation
    from pipeline.runs.transports.zenoh import online_stage

    runs = []
    for stage in (online_stage, None):
        oa = OnlineAssociation(window=2, resolution=resolution, hold=0, stage=stage,
                               robots_solve=stage is not None,
                               robots_check=stage is not None)
        runs.append((oa, _two_tracks_joined_through_the_window(oa, weak)))
    (zen, rz), (sim, rs) = runs
    assert rz["cut_history"] == rs["cut_history"] == 1
    assert zen.links.reason.tolist() == sim.links.reason.tolist()
    assert HISTORY in zen.links.reason.tolist()
    assert rz["history_rounds"] > 0 and rz["history_bytes"] > 0
    assert zen.is_conflict_free()


@pytest.mark.parametrize("resolution", ["paper", "paper-labels"])
def test_zenoh_online_step_counts_the_sets_alg1_resolved(resolution):
    """An online step's ``conflictive_sets`` over zenoh: the sets the robots rooted in their
    resolution passes, summed over the team, as the simulator counts them (one conflictive
    set, 0:0 and 0:1 joined through 1:0 and 2:0, beside a conflict-free one)."""
    from pipeline.consistency.engines.online import Frame, OnlineAssociation
    from pipeline.runs.transports.zenoh import online_stage

    links = Links([0, 1, 0, 1, 2], [0, 0, 1, 1, 1], [1, 2, 2, 2, 3], [0, 0, 0, 1, 0],
                  [0.9, 0.8, 0.3, 0.9, 0.4])
    recs = []
    for stage in (online_stage, None):
        oa = OnlineAssociation(window=2, resolution=resolution, stage=stage,
                               robots_solve=stage is not None, robots_check=stage is not None)
        frames = [Frame(0, 2), Frame(1, 3), Frame(2, 2), Frame(3, 1)]
        recs.append((oa, oa.add_step(frames, links)))
    (zen, rz), (sim, rs) = recs
    assert zen.links.reason.tolist() == sim.links.reason.tolist()
    assert rs["conflictive_sets"] >= 1
    assert rz["conflictive_sets"] == rs["conflictive_sets"]
    assert rz["conflictive_features"] == rs["conflictive_features"]


def test_a_history_file_that_is_not_one_is_a_one_line_error(tmp_path):
    """A team file's ``data.history`` entry that names a file of something else: the robot
    names the file and what writes it, in one line."""
    from pipeline.errors import InputError
    from pipeline.team.robot import load_history_inputs

    bad = tmp_path / "h.npz"
    bad.write_bytes(b"not an npz")
    with pytest.raises(InputError, match=r"^robot 3: data.history\[3\] .*h.npz is not a history "
                                         r"file of an online step") as e:
        load_history_inputs(bad, 3)
    assert "\n" not in str(e.value)
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(InputError, match="no array 'head'"):
        load_history_inputs(tmp_path / "other.npz", 0)
