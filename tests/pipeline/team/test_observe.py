"""A team started by hand (one ``robot`` process each) and a standalone observer: the same
run folder as the simulator's; each robot reads only its own data."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.__main__ import main
from pipeline.runs.formation import FormationConfig, run_formation


@pytest.fixture(autouse=True)
def _scene_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("FORMATION_MATCH_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


def _rows(path):
    return [tuple(line.split(",")[:6]) for line in Path(path).read_text().splitlines()]


def _start_robots(team_paths, tmp_path):
    """One ``python -m pipeline robot`` process per robot, as a user starts them by hand."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    procs = []
    for i, team in enumerate(team_paths):
        log = open(tmp_path / f"robot{i}.log", "wb")  # noqa: SIM115
        procs.append((subprocess.Popen(
            [sys.executable, "-m", "pipeline", "robot", "--team", str(team), "--id", str(i),
             "--result", str(tmp_path / f"robot{i}.json")], stdout=log,
            stderr=subprocess.STDOUT, env=env), log))
    return procs


def _observe_by_hand(team, tmp_path) -> None:
    """``team`` written to TEAM.json, its robots started by hand, ``observe`` writing
    ``tmp_path/obs``; every robot ends with exit 0."""
    from pipeline.team.teamfile import write_team

    path = write_team(tmp_path / "TEAM.json", team)
    procs = _start_robots([path] * team.n, tmp_path)
    try:
        assert main(["observe", "--team", str(path), "--out", str(tmp_path / "obs"),
                     "--timeout", "300", "--no-rerun"]) == 0
    finally:
        codes = _stop(procs)
    assert codes == [0] * team.n


def _stop(procs, timeout=60):
    codes = []
    for p, log in procs:
        try:
            codes.append(p.wait(timeout=timeout))
        except subprocess.TimeoutExpired:
            p.kill()
            codes.append(p.wait())
        log.close()
    return codes


def test_robots_by_hand_and_observe_give_the_simulators_run_folder(tmp_path):
    from pipeline.runs.transports.zenoh import team_options
    from pipeline.stages import merge_radius_for
    from pipeline.team.launcher import make_team

    # four robots on a ring (a cycle): each started by hand imports the program on its own
    cfg = dict(formation="ring", robots=4, graph="ring", seed=0, size=(160, 120), fusion=True,
               rerun=False)
    sim = run_formation(FormationConfig(out=str(tmp_path / "sim"), **cfg))
    c = FormationConfig(**cfg)
    import data_synth

    opts = team_options(c.features, c.max_features, None,
                        merge_radius=merge_radius_for(c.resolution, None),
                        resolution=c.resolution, fusion=True)
    opts["start_timeout_s"] = 120.0
    team = make_team("by-hand", data_synth.formation_edges("ring", 0, 4, "ring"),
                     {"kind": "formation", "formation": "ring", "seed": 0, "size": [160, 120],
                      "robots": 4, "graph": "ring"}, opts, n=4)
    _observe_by_hand(team, tmp_path)
    rows = _rows(tmp_path / "obs" / "links.csv")
    assert rows == _rows(sim / "links.csv")
    assert any(r[5] == "fusion-outlier" for r in rows[1:])
    report = json.loads((tmp_path / "obs" / "report.json").read_text())
    assert report["team"]["observed"] is True and report["team"]["lost"] == []
    assert report["after"]["conflictive_sets"] == 0
    # each robot's --result holds every decision it made, fusion cuts included
    status = {(int(r[0]), int(r[1]), int(r[2]), int(r[3])): (r[4], r[5]) for r in rows[1:]}
    fusion_cuts = 0
    for i in range(team.n):
        res = json.loads((tmp_path / f"robot{i}.json").read_text())["links"]
        for k, r, s, why in zip(res["link_nbr"], res["link_r"], res["link_s"],
                                zip(res["status"], res["reason"], strict=True), strict=True):
            key = (i, r, k, s) if i < k else (k, s, i, r)
            if why[1] == "fusion-outlier":
                fusion_cuts += 1
                assert status[key] == ("deleted", "fusion-outlier")
            if why[0] == "kept":
                assert status[key] == ("kept", "")
        assert len(res["fusion_cut"]) == len(res["link_nbr"])
    assert fusion_cuts > 0


def test_each_robot_given_only_its_own_links_file_runs(tmp_path):
    """Every robot on its own "machine" (folder): its TEAM.json copy names every robot's
    links file, but only its own exists there. The observer's links.csv equals the
    simulator's ``resolve`` of the whole file."""
    from pipeline.runs.transports.zenoh import write_robot_links
    from pipeline.team.launcher import make_team
    from pipeline.team.teamfile import write_team
    from pipeline.types import Links

    rng = np.random.default_rng(4)
    rows, seen = [], set()
    for _ in range(90):
        i, j = sorted(rng.choice(4, 2, replace=False).tolist())
        r, s = int(rng.integers(10)), int(rng.integers(10))
        if (i, r, j) not in seen and (j, s, i) not in seen:
            seen |= {(i, r, j), (j, s, i)}
            rows.append((i, r, j, s))
    rows.sort()
    q = rng.uniform(0.05, 0.95, len(rows)).round(3)
    links = Links(*np.array(rows).T, q)
    whole = tmp_path / "in.csv"
    whole.write_text("cam_i,feat_i,cam_j,feat_j,quality\n" + "".join(
        f"{a},{b},{c},{d},{x}\n" for (a, b, c, d), x in zip(rows, q, strict=True)))
    graph = tmp_path / "graph.csv"
    graph.write_text("".join(f"{i},{j}\n" for i in range(4) for j in range(i + 1, 4)))
    assert main(["resolve", "--links", str(whole), "--comm-graph", str(graph), "--resolution",
                 "evidence", "--out", str(tmp_path / "sim.csv")]) == 0
    names = [f"links-robot{i}.csv" for i in range(4)]
    team = make_team("own-files", [[i, j] for i in range(4) for j in range(i + 1, 4)],
                     {"kind": "links", "links": names, "features_per_camera": [10] * 4},
                     {"resolution": "evidence", "start_timeout_s": 120.0}, n=4)
    paths = []
    for i in range(4):
        home = tmp_path / f"machine{i}"
        home.mkdir()
        written = write_robot_links(home, links, 4)
        for k, p in enumerate(written):
            if k != i:
                p.unlink()  # only its own rows live on its machine
        team.path = None
        paths.append(write_team(home / "TEAM.json", team))
    (tmp_path / "observer").mkdir()
    obs_team = write_team(tmp_path / "observer" / "TEAM.json", team)
    procs = _start_robots(paths, tmp_path)
    try:
        assert main(["observe", "--team", str(obs_team), "--out", str(tmp_path / "obs"),
                     "--timeout", "300"]) == 0
    finally:
        codes = _stop(procs)
    assert codes == [0] * 4
    sim = _rows(tmp_path / "sim.csv")
    got = _rows(tmp_path / "obs" / "links.csv")
    assert got[0] == sim[0] and sorted(got[1:]) == sorted(sim[1:])
    assert any(r[4] == "deleted" for r in sim[1:])
    report = json.loads((tmp_path / "obs" / "report.json").read_text())
    assert report["after"]["conflictive_sets"] == 0 and report["links"] == len(rows)


def test_a_robot_reads_only_its_own_rows_and_refuses_a_foreign_file(tmp_path):
    from pipeline.errors import InputError
    from pipeline.team.robot import own_links_from_file

    f = tmp_path / "r1.csv"
    f.write_text("cam_i,feat_i,cam_j,feat_j\n0,1,1,2\n1,0,2,3\n")
    nbr, r, s, _ = own_links_from_file(f, 1, own_file=True)
    assert nbr.tolist() == [2, 0] and r.tolist() == [0, 2] and s.tolist() == [3, 1]
    with pytest.raises(InputError, match=r"r1.csv:3: link \(1,0\)-\(2,3\) does not touch robot 0"):
        own_links_from_file(f, 0, own_file=True)


def test_observe_refuses_a_team_without_observer_or_photographs_in_two_folders(tmp_path,
                                                                               capsys):
    doc = {"version": 1, "name": "two", "comm_edges": [[0, 1]],
           "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7447"},
                      {"id": 1, "endpoint": "tcp/127.0.0.1:7448"}],
           "data": {"kind": "formation", "formation": "line", "robots": 2, "seed": 0}}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    assert main(["observe", "--team", str(tmp_path / "T.json"), "--out",
                 str(tmp_path / "o")]) == 2
    assert "has no observer endpoint" in capsys.readouterr().err
    doc["observer"] = {"endpoint": "tcp/127.0.0.1:7449"}
    doc["data"] = {"kind": "images", "images": ["a/x.jpg", "b/y.jpg"]}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    assert main(["observe", "--team", str(tmp_path / "T.json"), "--out",
                 str(tmp_path / "o")]) == 2
    assert "from one folder, data.images names 2" in capsys.readouterr().err
    cam = {"K": np.eye(3).tolist(), "R": np.eye(3).tolist(), "t": [0, 0, 1]}
    doc["data"] = {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1],
                   "keypoints": ["k0.csv", "k1.csv"], "cameras": [cam, cam]}
    doc["options"] = {"fusion": True}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    assert main(["observe", "--team", str(tmp_path / "T.json"), "--out",
                 str(tmp_path / "o")]) == 2
    assert "not the fusion cuts its robots make; set option fusion false" in \
        capsys.readouterr().err
    doc["data"] = {"kind": "online-match", "step": 0, "window": 2, "frames": ["f0", "f1"],
                   "store": ["r0", "r1"]}
    doc["options"] = {}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    assert main(["observe", "--team", str(tmp_path / "T.json"), "--out",
                 str(tmp_path / "o")]) == 2
    assert "one step's matching of an online run" in capsys.readouterr().err
    assert main(["observe", "--team", str(tmp_path / "none.json"), "--out",
                 str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err
    for bad in ("0", "-1", "nan", "1e9"):
        assert main(["observe", "--team", str(tmp_path / "T.json"), "--out",
                     str(tmp_path / "o"), "--timeout", bad]) == 2
        assert "--timeout" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_observe_refuses_a_team_of_photographs_missing_on_its_machine_before_it_listens(
        tmp_path, capsys, monkeypatch):
    """The observer of a team of photographs loads them once every robot has published: a
    photograph missing on its machine (a team file copied without them) was found only then,
    as "cannot read it as an image", and the team's whole run was lost. It is refused before
    the observer listens, naming the file."""
    import pipeline.team.observe as observing

    def listened(*a, **k):
        raise AssertionError("the observer listened")

    monkeypatch.setattr(observing, "observe_team", listened)
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.jpg").write_bytes(b"x")
    doc = {"version": 1, "name": "two", "comm_edges": [[0, 1]],
           "robots": [{"id": 0, "endpoint": "tcp/127.0.0.1:7447"},
                      {"id": 1, "endpoint": "tcp/127.0.0.1:7448"}],
           "observer": {"endpoint": "tcp/127.0.0.1:7449"},
           "data": {"kind": "images", "images": ["photos/a.jpg", "photos/b.jpg"]}}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    assert main(["observe", "--team", str(tmp_path / "T.json"), "--out",
                 str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"error: team 'two': data.images[1] {str(tmp_path / 'photos' / 'b.jpg')!r}: no such " \
           "file; the observer needs the team's photographs on this machine too" in err
    assert not (tmp_path / "o").exists()


def test_photographs_by_hand_and_observe_give_the_launchers_run_folder(sceaux_small,
                                                                       tmp_path):
    """Four photographs, photo defaults, robots started by hand: the observer's run folder
    has the links of ``run-images --transport zenoh`` (equal to the simulator's without
    fusion)."""
    from pipeline.commgraph import comm_graph
    from pipeline.inputs.photos import in_content_order, load_folder
    from pipeline.runs.images import ImagesConfig
    from pipeline.runs.transports.zenoh import images_team

    args = ["run-images", str(sceaux_small), "--graph", "complete", "--max-size", "320",
            "--no-fusion", "--no-rerun"]
    assert main([*args, "--out", str(tmp_path / "sim")]) == 0
    config = ImagesConfig(str(sceaux_small), "complete", max_size=320)
    # cameras in the order run-images gives them (by content, pipeline.inputs.photos)
    views = in_content_order(load_folder(sceaux_small, max_size=320))
    team = images_team(config, views, comm_graph("complete", [v.name for v in views]))
    team.options["start_timeout_s"] = 120.0
    _observe_by_hand(team, tmp_path)
    sim = (tmp_path / "sim" / "links.csv").read_text().splitlines()
    assert (tmp_path / "obs" / "links.csv").read_text().splitlines() == sim
    assert len(sim) > 500
    rep = json.loads((tmp_path / "obs" / "report.json").read_text())
    sim_rep = json.loads((tmp_path / "sim" / "report.json").read_text())
    assert rep["features_per_camera"] == sim_rep["features_per_camera"]
    assert rep["team"]["observed"] is True and rep["fusion"]["enabled"] is False
    assert (tmp_path / "obs" / "sparse").is_dir()


def test_loss_at_one_robot_is_learnt_by_all_and_the_fault_tolerant_rule_runs(tmp_path):
    """Robot 2 alone injects message loss (its own option): every robot learns it from its
    neighbours and all run the fault-tolerant Alg. 1, as the simulator does on a lossy
    network."""
    from pipeline.runs.transports.zenoh import write_robot_links
    from pipeline.team.launcher import launch_team, make_team
    from pipeline.types import Links

    links = Links([0, 0, 1, 2], [0, 1, 0, 0], [1, 3, 2, 3], [0, 0, 1, 1], [0.9, 0.2, 0.8, 0.7])
    paths = [str(p) for p in write_robot_links(tmp_path, links, 4)]
    team = make_team("lossy-one", [[0, 1], [1, 2], [2, 3], [0, 3]],
                     {"kind": "links", "links": paths, "features_per_camera": [2, 2, 2, 2]},
                     {"resolution": "evidence"}, n=4)
    team.robot_options = {2: {"drop_prob": 0.3}}
    run = launch_team(team, tmp_path / "work")
    assert sorted(run.results) == [0, 1, 2, 3]
    assert {h["resolution"] for h, _ in run.results.values()} == {"paper"}
    assert all(h["counters"]["dropped"] == 0 for i, (h, _) in run.results.items() if i != 2)
    team.robot_options = {}
    run = launch_team(team, tmp_path / "work2")
    assert {h["resolution"] for h, _ in run.results.values()} == {"evidence"}


def test_the_observer_names_a_robot_that_never_started_or_failed():
    import threading

    from pipeline.errors import TeamError
    from pipeline.team.launcher import make_team
    from pipeline.team.observe import observe_team
    from pipeline.transport.zenoh_transport import key, open_session

    data = {"kind": "links", "links": "x.csv", "features_per_camera": [1, 1]}
    team = make_team("quiet", [[0, 1]], data, n=2)
    with pytest.raises(TeamError, match=r"no robot published a result within 0.5 s; robot 0 "
                                        r"\(tcp/127.0.0.1:\d+\) never started"):
        observe_team(team, timeout_s=0.5)
    # a robot that reports a failure ends the observation with its message
    team = make_team("failing", [[0, 1]], data, n=2)
    stop = threading.Event()

    def robot_one():
        s = open_session([team.endpoint(1)], [team.observer], "robot 1")
        try:
            while not stop.wait(0.05):
                s.put(key(team.name, "status", 1), "failed: no such image")
        finally:
            s.close()

    t = threading.Thread(target=robot_one)
    t.start()
    try:
        with pytest.raises(TeamError, match=r"robot 1 \(tcp/127.0.0.1:\d+\) failed: no such image"):
            observe_team(team, timeout_s=60)
    finally:
        stop.set()
        t.join()


def test_a_robot_killed_mid_run_is_reported_lost_by_the_observer(tmp_path):
    """kill -9 of one hand-started robot: its Zenoh session vanishes, the survivors finish
    without it, the observer reports it lost and writes a conflict-free run folder."""
    import signal
    import time

    from pipeline.consistency.centralized import is_conflict_free
    from pipeline.runs.transports.zenoh import team_options
    from pipeline.team.launcher import make_team
    from pipeline.team.teamfile import write_team
    from pipeline.types import Links

    opts = team_options(max_features=2000, round_timeout_s=1.0, merge_radius=2.0)
    opts["start_timeout_s"] = 120.0
    edges = [[i, j] for i in range(4) for j in range(i + 1, 4)]
    team = make_team("kill-one", edges, {"kind": "formation", "formation": "complete",
                                         "seed": 0, "size": [160, 120], "robots": 4,
                                         "graph": "complete"}, opts, n=4)
    path = write_team(tmp_path / "TEAM.json", team)
    procs = _start_robots([path] * 4, tmp_path)
    out = {}

    def observe():
        out["code"] = main(["observe", "--team", str(path), "--out", str(tmp_path / "obs"),
                            "--timeout", "300", "--no-rerun"])

    import threading

    t = threading.Thread(target=observe)
    t.start()
    try:
        log = tmp_path / "robot2.log"
        for _ in range(1200):  # until robot 2 has met its neighbours (at most 120 s)
            if log.exists() and "neighbours heard" in log.read_text():
                break
            time.sleep(0.1)
        procs[2][0].send_signal(signal.SIGKILL)
        t.join(timeout=300)
    finally:
        codes = _stop(procs)
    assert not t.is_alive() and out["code"] == 0
    assert codes[2] == -signal.SIGKILL and [codes[i] for i in (0, 1, 3)] == [0, 0, 0]
    report = json.loads((tmp_path / "obs" / "report.json").read_text())
    assert report["team"]["lost"] == [2] and report["team"]["robots"]["2"]["result"] is None
    assert report["team"]["robots"]["2"]["started"] is True  # killed, not never started
    rows = [r.split(",") for r in (tmp_path / "obs" / "links.csv").read_text().splitlines()[1:]]
    kept = [r for r in rows if r[4] == "kept"]
    assert not any("2" in (r[0], r[2]) for r in kept)
    links = Links(*([int(r[k]) for r in kept] for k in (0, 1, 2, 3)))
    assert is_conflict_free(report["features_per_camera"], links)
    assert report["after"]["conflictive_sets"] == 0


def _links_team_file(tmp_path, name: str, n: int, edges, **options) -> str:
    """A TEAM.json of ``n`` robots holding one feature each and the link (0,0)-(1,0), on free
    loopback ports, with an observer; its path."""
    from pipeline.team.launcher import free_ports

    p = free_ports(n + 1)
    doc = {"version": 1, "name": name, "comm_edges": edges,
           "robots": [{"id": i, "endpoint": f"tcp/127.0.0.1:{p[i]}"} for i in range(n)],
           "observer": {"endpoint": f"tcp/127.0.0.1:{p[n]}"},
           "data": {"kind": "links", "links": "in.csv", "features_per_camera": [1] * n},
           "options": options}
    (tmp_path / "T.json").write_text(json.dumps(doc))
    (tmp_path / "in.csv").write_text("0,0,1,0\n")
    return str(tmp_path / "T.json")


def test_a_timeout_shorter_than_the_teams_start_is_warned(tmp_path, capsys):
    """observe --timeout below the team's start_timeout_s: robots still starting when it gives
    up would publish to no one; said before it waits."""
    team = _links_team_file(tmp_path, "early", 2, [[0, 1]], start_timeout_s=30)
    assert main(["observe", "--team", team, "--out", str(tmp_path / "o"),
                 "--timeout", "0.5"]) == 2  # no robot was started
    err = capsys.readouterr().err
    assert "--timeout 0.5 s is shorter than the team's start_timeout_s (30 s)" in err


def test_the_observer_evaluates_on_the_teams_comm_edges(tmp_path):
    """A team file whose comm_edges differ from its formation's default graph (a line of three
    robots that all talk to each other): the robots match over comm_edges; the observer took
    the formation's graph and refused their links ('cameras 0 and 2 are not neighbours')."""
    from pipeline.runs.transports.zenoh import team_options
    from pipeline.stages import merge_radius_for
    from pipeline.team.launcher import make_team

    c = FormationConfig(formation="line", robots=3, graph=None, seed=5, size=(160, 120))
    opts = team_options(c.features, 300, None, merge_radius=merge_radius_for(c.resolution, None),
                        resolution=c.resolution, fusion=False)
    opts["start_timeout_s"] = 120.0
    edges = np.array([[0, 1], [0, 2], [1, 2]])
    team = make_team("by-hand-triangle", edges,
                     {"kind": "formation", "formation": "line", "seed": 5, "size": [160, 120],
                      "robots": 3, "graph": None}, opts, n=3)
    _observe_by_hand(team, tmp_path)
    report = json.loads((tmp_path / "obs" / "report.json").read_text())
    assert report["comm_edges"] == edges.tolist()
    rows = _rows(tmp_path / "obs" / "links.csv")[1:]
    assert any({int(r[0]), int(r[2])} == {0, 2} for r in rows)  # links over the added edge


def _observe_with_robot_one(team, header, timeout_s=60):
    """observe_team(team) while a stand-in robot 1 publishes a result of ``header``."""
    import threading

    from pipeline.team.observe import observe_team
    from pipeline.transport.wire import encode_packet
    from pipeline.transport.zenoh_transport import key, open_session

    stop = threading.Event()
    result = encode_packet({"id": 1, **header}, [("result", {})])

    def robot_one():
        s = open_session([team.endpoint(1)], [team.observer], "robot 1")
        try:
            while not stop.wait(0.05):
                s.put(key(team.name, "result", 1), result)
        finally:
            s.close()

    t = threading.Thread(target=robot_one)
    t.start()
    try:
        return observe_team(team, timeout_s=timeout_s)
    finally:
        stop.set()
        t.join()


def test_a_robot_never_started_and_written_off_by_its_neighbours_ends_the_observation():
    """Robot 0 never starts; robot 1 wrote it off at its start timeout and published: the
    observer reports robot 0 lost as soon as robot 1's result is in (a written-off robot is
    never taken back), instead of waiting out its --timeout."""
    import time

    from pipeline.team.launcher import make_team

    team = make_team("written-off", [[0, 1]], {"kind": "links", "links": "x.csv",
                                               "features_per_camera": [1, 1]}, n=2)
    t0 = time.monotonic()
    run = _observe_with_robot_one(team, {"counters": {"outcome": "partitioned",
                                                      "written_off": {"0": "start"}}})
    assert time.monotonic() - t0 < 30
    assert sorted(run.results) == [1] and sorted(run.killed) == [0]


def test_the_observer_refuses_a_result_of_another_team_file():
    """Robot 1 ran with a TEAM.json naming another rule than the observer's: the observer
    stops with an InputError naming it, where it used to write a run folder whose report
    claimed the rule the robots did not run."""
    from pipeline.errors import InputError
    from pipeline.team.launcher import make_team

    team = make_team("other-file", [[0, 1]], {"kind": "links", "links": "x.csv",
                                              "features_per_camera": [1, 1]}, n=2)
    terms = {**team.shared_terms(), "resolution": "paper"}
    with pytest.raises(InputError, match=r"robot 1 \(tcp/127.0.0.1:\d+\) ran with another team "
                                         r"file than the observer's \(resolution 'paper' there"):
        _observe_with_robot_one(team, {"counters": {}, "team_terms": terms}, timeout_s=20)


def test_a_result_arriving_after_the_observer_closed_raises_nothing():
    """A robot's result delivered while the observer closes (it stopped on another robot's
    error) used to raise ZError in Zenoh's callback thread, printed as a traceback."""
    from types import SimpleNamespace

    from pipeline.team.launcher import Observer, make_team
    from pipeline.transport.wire import encode_packet

    team = make_team("closing", [[0, 1]], {"kind": "links", "links": "x.csv",
                                           "features_per_camera": [1, 1]}, n=2)
    obs = Observer(team)
    obs.close()
    packet = encode_packet({"id": 1}, [("result", {})])
    obs._on_result(SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: packet)))
    assert 1 in obs.results


def test_an_observer_started_after_the_robots_ended_says_they_may_have_ended(tmp_path):
    """Two robots that ran and gave up repeating their results (no observer yet), then the
    observer: it cannot tell them from robots that never ran, and said only 'never started'
    of robots that had run; it now says that they may have ended before it listened."""
    import threading

    from pipeline.errors import TeamError
    from pipeline.team.launcher import make_team
    from pipeline.team.observe import observe_team
    from pipeline.team.robot import run_robot_process

    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n")
    data = {"kind": "links", "links": "in.csv", "features_per_camera": [1, 1]}
    team = make_team("ended-early", [[0, 1]], data, n=2)
    team.options["start_timeout_s"] = 1.0
    team.path = tmp_path / "TEAM.json"
    codes = [None, None]

    def run(i):
        codes[i] = run_robot_process(team, i)

    threads = [threading.Thread(target=run, args=(i,)) for i in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert codes == [0, 0]
    with pytest.raises(TeamError, match=r"robot 0 \(tcp/127.0.0.1:\d+\) never started, or it "
                                        r"ended before this observer listened"):
        observe_team(team, timeout_s=0.5)


def test_a_team_whose_comm_graph_splits_is_warned_by_the_observer(tmp_path, capsys):
    """A hand-written team whose comm_edges leave robot 2 with no neighbour: no robot, no
    observer said a word (run-images warns of a split graph); the observer now says so
    before it waits, naming the fix."""
    team = _links_team_file(tmp_path, "split", 3, [[0, 1]], start_timeout_s=0.5)
    assert main(["observe", "--team", team, "--out", str(tmp_path / "o"),
                 "--timeout", "0.5"]) == 2  # no robot was started
    err = capsys.readouterr().err
    assert ("the comm graph splits the 3 robots into 2 groups that never match each other: "
            "their features cannot be associated across the groups (add comm_edges to the "
            "team file)") in err


def test_a_lost_robot_whose_neighbours_all_heard_it_to_the_end_is_unreported_not_lost():
    """Robot 1 of a line 0-1-2 published nothing (the observer's path to it was cut) while
    robots 0 and 2 finished with it: it is named unreported; robot 3, written off by its
    neighbour 2, and robot 4, whose neighbour published nothing, are not."""
    from pipeline.team.launcher import make_team
    from pipeline.team.observe import unreported

    team = make_team("unheard", [[0, 1], [1, 2], [2, 3], [3, 4]],
                     {"kind": "links", "links": "x.csv", "features_per_camera": [1] * 5}, n=5)
    done = ({"counters": {"outcome": "done", "written_off": {}}}, {})
    results = {0: done, 2: ({"counters": {"outcome": "partitioned",
                                          "written_off": {"3": "silent"}}}, {})}
    assert unreported(team, results, [1, 3, 4]) == [1]


def test_a_robot_whose_receipts_were_lost_is_acknowledged_before_the_observer_ends(
        tmp_path, monkeypatch):
    """Every receipt sent before the observer holds all the results is lost (as with a link
    the robot closed while the observer was paused, ``kill -STOP``): the observer stays to
    acknowledge the repeats, so no robot repeats its result until ``start_timeout_s``."""
    from pipeline.team.launcher import Observer, make_team
    from pipeline.team.teamfile import write_team

    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j,quality\n0,0,1,0,0.9\n"
                                     "0,1,2,1,0.8\n1,2,2,0,0.7\n0,2,1,1,0.6\n")
    team = make_team("lost-acks", [[0, 1], [0, 2], [1, 2]],
                     {"kind": "links", "links": "in.csv", "features_per_camera": [5] * 3},
                     {"resolution": "evidence", "start_timeout_s": 10.0}, n=3)
    real_ack = Observer.ack

    def ack_once_all_in(self, i):
        with self.cv:
            all_in = all(k in self.results for k in range(self.team.n))
        if all_in:
            real_ack(self, i)

    monkeypatch.setattr(Observer, "ack", ack_once_all_in)
    path = write_team(tmp_path / "TEAM.json", team)
    procs = _start_robots([path] * team.n, tmp_path)
    try:
        assert main(["observe", "--team", str(path), "--out", str(tmp_path / "obs"),
                     "--timeout", "120"]) == 0
    finally:
        codes = _stop(procs)
    assert codes == [0] * team.n
    for i in range(team.n):
        log = (tmp_path / f"robot{i}.log").read_text()
        assert f"[robot {i}] done in" in log and "observer did not acknowledge" not in log


def test_an_empty_out_is_named_as_empty(tmp_path, capsys):
    """``observe --out ''`` (an unset variable) was refused as ``--out '.'``, a value the user
    never gave."""
    team = _links_team_file(tmp_path, "empty-out", 2, [[0, 1]])
    assert main(["observe", "--team", team, "--out", "", "--timeout", "60"]) == 2
    err = capsys.readouterr().err
    assert "error: --out '' is empty (an unset variable?); give a folder name" in err


def test_a_token_back_after_a_lapse_is_a_robot_still_running():
    """A robot's liveliness token that vanished (its link to the observer lapsed) and came
    back: the observer kept the first vanish time, so the robot would be counted lost
    GRACE_S after it, running or not; the time is now forgotten when the token is back."""
    import threading
    from types import SimpleNamespace

    import zenoh

    from pipeline.team.observe import TeamObserver

    obs = object.__new__(TeamObserver)  # its bookkeeping only: no session
    obs.cv = threading.Condition()
    obs.vanished, obs.alive, obs.holding = {}, set(), set()
    obs.ended, obs.results = {}, {}
    key = "formation-match/team/live/3"
    obs._on_live(SimpleNamespace(key_expr=key, kind=zenoh.SampleKind.PUT))
    obs._on_live(SimpleNamespace(key_expr=key, kind=zenoh.SampleKind.DELETE))
    assert 3 in obs.vanished and 3 not in obs.holding
    obs._on_live(SimpleNamespace(key_expr=key, kind=zenoh.SampleKind.PUT))
    assert obs.vanished == {} and obs.holding == {3} and obs.alive == {3}


def test_the_observer_session_has_the_robots_lease(monkeypatch):
    """The observer opened its Zenoh session with Zenoh's default lease (10 s) while the
    robots' sessions outlast ``round_timeout_s`` (70 s by default): a pause of the observer
    longer than 10 s closed its links. It now takes the lease of the team's longest round
    timeout (per-robot overrides included)."""
    from pipeline.team import launcher
    from pipeline.transport import zenoh_transport

    seen = {}

    def fake_open(listen, connect, who, round_timeout_s=None):
        seen["round_timeout_s"] = round_timeout_s
        raise RuntimeError("stop here")

    monkeypatch.setattr(zenoh_transport, "open_session", fake_open)
    team = launcher.make_team("lease", [[0, 1]], {"kind": "links", "links": "x.csv",
                                                  "features_per_camera": [1, 1]}, n=2)
    team.robot_options = {1: {"round_timeout_s": 45.0}}
    with pytest.raises(RuntimeError, match="stop here"):
        launcher.Observer(team)
    assert seen["round_timeout_s"] == 45.0


def test_an_observer_whose_timeout_ends_before_running_robots_publish_says_to_raise_it():
    """Every robot runs (its liveliness token is up) but none has published when --timeout
    ends: the error said only "robot 0 (…) did not publish"; it now says the robot is still
    running and to give the team a longer --timeout."""
    import threading

    from pipeline.errors import TeamError
    from pipeline.team.launcher import make_team
    from pipeline.team.observe import observe_team
    from pipeline.transport.zenoh_transport import key, open_session

    team = make_team("slow", [[0, 1]], {"kind": "links", "links": "x.csv",
                                        "features_per_camera": [1, 1]}, n=2)
    stop = threading.Event()
    up = threading.Barrier(3)

    def robot(i):
        s = open_session([team.endpoint(i)], [team.observer], f"robot {i}")
        token = s.liveliness().declare_token(key(team.name, "live", i))
        try:
            up.wait()
            stop.wait(30)
        finally:
            token.undeclare()
            s.close()

    threads = [threading.Thread(target=robot, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    try:
        up.wait()
        with pytest.raises(TeamError, match=r"no robot published a result within 2 s; robot 0 "
                                            r"\(tcp/127.0.0.1:\d+\) did not publish: it is "
                                            r"still running; give the team longer, a --timeout "
                                            r"above 2 s$"):
            observe_team(team, timeout_s=2)
    finally:
        stop.set()
        for t in threads:
            t.join()
