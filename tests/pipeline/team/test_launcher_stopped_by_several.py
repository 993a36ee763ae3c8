"""``launch_team(..., stop_at_loss=True)`` with two robot processes that end without
publishing in the same poll: the team recorded only the first it found gone
(``TeamRun.stopped_at``), so the other was not counted lost (an online step's
``match_robots_lost``, ``images_lost`` or fusion ``frames_lost`` named one robot). Every
robot gone when the team is stopped is recorded (``TeamRun.stopped_by``)."""

import os
import signal
import time
from pathlib import Path

from zygote_teams import links_team

from pipeline.team.launcher import TeamRun, launch_team, lost_robots


def _state(pid: int) -> str | None:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return None


def _robot_pid(team_path: Path, i: int) -> int:
    """The pid of ``python -m pipeline robot --team TEAM --id I`` (its own interpreter)."""
    want = ["--team", str(team_path), "--id", str(i)]
    for cmd in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            args = cmd.read_bytes().decode(errors="replace").split("\0")
        except OSError:
            continue
        if any(args[k:k + 4] == want for k in range(len(args))):
            return int(cmd.parent.name)
    raise AssertionError(f"no process of robot {i}")


def _ended(pid: int) -> None:
    """Wait until ``pid`` has ended (a zombie until its parent, the launcher, polls it)."""
    end = time.monotonic() + 10
    while _state(pid) not in ("Z", None):
        assert time.monotonic() < end, f"process {pid} did not end"
        time.sleep(0.01)


def test_two_robots_ended_in_the_same_poll_are_both_lost(tmp_path):
    team, _ = links_team(tmp_path, "two-gone", {"round_timeout_s": 20.0})
    work = tmp_path / "w"

    def log(line):
        # the launcher just froze robot 2 (fault injection) and has not looked at the
        # processes again: robots 1 and 3 end before it does
        if line.startswith("kill -STOP robot 2 "):
            others = [_robot_pid(work / "TEAM.json", i) for i in (1, 3)]
            for pid in others:
                os.kill(pid, signal.SIGKILL)
            for pid in others:
                _ended(pid)

    run = launch_team(team, work, kill=(2, "started", 0.0, 3600.0), stop_at_loss=True,
                      timeout_s=120, fork=False, log=log)
    assert lost_robots(run) == [1, 3]
    assert run.stopped_by == [1, 3]
    assert not {1, 3} & set(run.results)


def test_lost_robots_names_every_robot_the_team_was_stopped_by():
    run = TeamRun(team=None, stopped_by=[0, 3], killed={3: 1.0})
    assert lost_robots(run) == [0, 3]
    run = TeamRun(team=None, stopped_by=[1], results={0: ({}, {})}, finished_at={0: 1.0})
    assert lost_robots(run, {2: [0]}) == [1, 2]
