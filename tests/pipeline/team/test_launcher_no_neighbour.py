"""A robot process that heard no neighbour in its start handshake ends with exit code 3
(``RobotMissingError``: its neighbours were lost before it heard them, or it cannot reach
them). ``launch_team`` took it for a failure ("robot 3 ... failed with exit code 3") and
the team's work was lost, also for an online step, which starts a team that lost a robot
again. With ``stop_at_loss`` it is now lost as a killed robot is; without it (a batch run),
it is lost when every neighbour of it was lost too, and still an error naming it when they
ran (it could not reach live neighbours: an address or the network is wrong)."""

import json
import subprocess

import pytest

from pipeline.errors import TeamError
from pipeline.team import launcher
from pipeline.team.launcher import free_ports, launch_team, lost_robots, make_team

# robot 3's only neighbour is robot 0
LINKS = "cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,1,2,0\n0,2,3,0\n"
EDGES = [[0, 1], [1, 2], [0, 2], [0, 3]]
FPC = [3, 1, 1, 1]
START_S = 3.0  # the start handshake's limit: robot 3 gives up after it


@pytest.fixture
def cut_off(monkeypatch):
    """Robot 3 (started as its own interpreter, ``fork=False``) on a host cut off from the
    others: its copy of the team file moves its own endpoint and robot 0's to ports where
    nothing listens, so neither end ever hears the other."""
    real = subprocess.Popen

    def popen(args, *a, **kw):
        args = list(args)
        if args[-2:] == ["--id", "3"]:
            k = args.index("--team") + 1
            doc = json.loads(open(args[k]).read())
            for r, port in zip((0, 3), free_ports(2), strict=True):
                doc["robots"][r]["endpoint"] = f"tcp/127.0.0.1:{port}"
            args[k] = args[k].replace("TEAM.json", "TEAM-robot3.json")
            with open(args[k], "w") as f:
                json.dump(doc, f)
        return real(args, *a, **kw)

    monkeypatch.setattr(launcher.subprocess, "Popen", popen)


def _team(tmp_path):
    links = tmp_path / "in.csv"
    links.write_text(LINKS)
    return make_team("no-neighbour", EDGES, {"kind": "links", "links": str(links),
                                             "features_per_camera": FPC},
                     # closed_at_start off: robot 3 is not told of robot 0's end by the
                     # launcher (as in a team started by hand), so it hears no neighbour
                     {"round_timeout_s": 2.0, "start_timeout_s": START_S,
                      "closed_at_start": False}, n=4)


def test_with_stop_at_loss_it_is_lost_as_a_killed_robot(tmp_path, cut_off):
    run = launch_team(_team(tmp_path), tmp_path / "w", stop_at_loss=True, timeout_s=120,
                      fork=False)
    assert run.exit_codes[3] == 3 and 3 not in run.results
    assert run.stopped_by == [3] and lost_robots(run) == [3]


def test_in_a_batch_run_it_is_lost_when_its_neighbours_were(tmp_path, cut_off):
    # robot 0, its only neighbour, killed as it starts: the others finish without both
    run = launch_team(_team(tmp_path), tmp_path / "w", kill=(0, "started", 0.0),
                      timeout_s=120, fork=False)
    assert run.exit_codes[3] == 3 and sorted(run.results) == [1, 2]
    assert lost_robots(run) == [0, 3]


def test_in_a_batch_run_it_is_an_error_when_its_neighbours_ran(tmp_path, cut_off):
    with pytest.raises(TeamError, match=r"^robot 3 \(tcp/[^)]*\) failed with exit code 3: "
                                        r"error: robot 3: neighbour robot 0 .* did not answer"):
        launch_team(_team(tmp_path), tmp_path / "w", timeout_s=120, fork=False)
