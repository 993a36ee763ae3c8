"""The robot program (pipeline.team.robot): its helpers that need no team running, and its
--result file."""

import json
import pstats
import re
from types import SimpleNamespace

import pytest

from pipeline.team.robot import _profiled
from pipeline.team.teamfile import PROFILE_DIR_ENV


def test_the_profile_hook_writes_the_robots_statistics_only_when_asked(tmp_path, monkeypatch):
    team = SimpleNamespace(name="resolve")
    monkeypatch.delenv(PROFILE_DIR_ENV, raising=False)
    assert _profiled(lambda t, i, tr: (t.name, i), team, 3, None) == ("resolve", 3)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setenv(PROFILE_DIR_ENV, str(tmp_path / "prof"))
    assert _profiled(lambda t, i, tr: sum(range(1000)), team, 3, None) == 499500
    (f,) = (tmp_path / "prof").glob("resolve-3-*.pstats")
    assert pstats.Stats(str(f)).total_calls > 0

    def fails(t, i, tr):
        raise RuntimeError("robot stopped")

    with pytest.raises(RuntimeError, match="robot stopped"):  # written on failure too
        _profiled(fails, SimpleNamespace(name="fusion"), 1, None)
    assert len(list((tmp_path / "prof").glob("fusion-1-*.pstats"))) == 1


def _two_robots(tmp_path, name: str):
    """A links team of two robots and one link, without observer, its file in tmp_path."""
    from pipeline.team.launcher import make_team

    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n")
    team = make_team(name, [[0, 1]], {"kind": "links", "links": "in.csv",
                                      "features_per_camera": [1, 1]}, n=2)
    team.path = tmp_path / "TEAM.json"
    team.observer = None
    return team


def _run_both(run) -> list:
    """``run(i)`` for robots 0 and 1 in two threads; their exit codes."""
    import threading

    codes = [None, None]

    def one(i):
        codes[i] = run(i)

    threads = [threading.Thread(target=one, args=(i,)) for i in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    return codes


def test_two_robots_given_one_result_file_do_not_replace_each_others(tmp_path):
    """Robots 0 and 1 both given ``--result same.json`` (no --overwrite): the first to end
    writes it, the second keeps it as it is and exits 2 naming it, where it used to replace
    it silently and both exited 0."""
    from pipeline.team.robot import run_robot_process

    team = _two_robots(tmp_path, "same-result")
    same = tmp_path / "same.json"
    codes = _run_both(lambda i: run_robot_process(team, i, str(same)))
    assert sorted(codes) == [0, 2]
    assert json.loads(same.read_text())["id"] == codes.index(0)


def test_ctrl_c_while_the_observer_is_awaited_names_the_result_written(tmp_path, monkeypatch,
                                                                       capsys):
    """A robot whose ``--result`` is written and which is interrupted while it repeats its
    result to an observer (not started yet): the one line names the result as in place,
    where it said that nothing was written."""
    from pipeline.__main__ import interruptible
    from pipeline.team.robot import run_robot_process
    from pipeline.transport.zenoh_transport import ZenohTransport

    publish = ZenohTransport.publish_result

    def interrupted(self, *a, **k):
        if self.robot_id == 0:
            raise KeyboardInterrupt
        return publish(self, *a, **k)

    monkeypatch.setattr(ZenohTransport, "publish_result", interrupted)
    team = _two_robots(tmp_path, "ctrl-c-result")
    result = tmp_path / "r0.json"
    codes = _run_both(lambda i: interruptible("robot", lambda: run_robot_process(
        team, 0, str(result))) if i == 0 else run_robot_process(team, 1))
    assert codes == [130, 0]
    assert json.loads(result.read_text())["id"] == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("interrupted:")]
    assert lines == [f"interrupted: robot stopped; already in place, complete: {str(result)!r}"]


def test_a_link_between_robots_that_do_not_talk_names_the_link_and_the_edge(tmp_path):
    """A links team whose comm_edges leave out a pair that a link joins: each robot said only
    'link to camera J'; it now names the link, its file and the edge to add."""
    from pipeline.errors import TeamError
    from pipeline.team.launcher import launch_team, make_team

    links = tmp_path / "in.csv"
    links.write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,1,2,1\n0,1,2,0\n")
    team = make_team("t", [[0, 1], [1, 2]], {"kind": "links", "links": str(links),
                                              "features_per_camera": [2, 2, 2]}, n=3)
    f = re.escape(str(links))
    with pytest.raises(TeamError, match=(
            rf"robot 0: link \(0,1\)-\(2,0\) of {f} joins camera 2, which is not its neighbour "
            rf"in the team's comm_edges; add \[0, 2\] to comm_edges or remove the link|"
            rf"robot 2: link \(2,0\)-\(0,1\) of {f} joins camera 0, which is not its neighbour "
            rf"in the team's comm_edges; add \[0, 2\] to comm_edges or remove the link")):
        launch_team(team, tmp_path / "team", timeout_s=60)
