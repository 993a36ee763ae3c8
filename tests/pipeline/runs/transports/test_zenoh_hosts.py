"""FORMATION_MATCH_HOSTS (pipeline.runs.transports.zenoh.HOSTS_ENV): the robots of every team
the zenoh transport starts each on a host of its own — a Linux network namespace, one cable per
comm edge of its team, ``netns:RATE`` capping every cable — with the results of the loopback
(:func:`pipeline.team.netns.launch_team_on_hosts`). A value it cannot use is refused by name
before any work; the namespaces are gone when a team ends, fails or is interrupted."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.__main__ import main
from pipeline.errors import InputError, TeamError
from pipeline.runs.transports import zenoh
from pipeline.team import launcher, netns

WHY = netns.unavailable()
needs_namespaces = pytest.mark.skipif(WHY is not None, reason=f"no network namespaces: {WHY}")

ROOT = Path(__file__).resolve().parents[4]
#: the online run of the test: 3 robots on a ring, 2 steps of window 2
ONLINE = ["run-formation", "--steps", "2", "--window", "2", "--size", "160x120",
          "--max-features", "120", "--robots", "3", "--graph", "ring", "--no-rerun"]


def _namespaces(pid: int) -> list[str]:
    """The namespaces of rigs made by process ``pid`` (``fm<pid>x<k>-<i>``)."""
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True,
                            check=True).stdout.split("\n")
    return [line.split(" ")[0] for line in listed if line.startswith(f"fm{pid}x")]


@pytest.mark.parametrize(("value", "named"), [
    ("docker", "FORMATION_MATCH_HOSTS='docker': choose loopback"),
    ("netns:fast", "FORMATION_MATCH_HOSTS='netns:fast': 'fast' is not a bandwidth"),
    ("netns:0mbit", "FORMATION_MATCH_HOSTS='netns:0mbit': '0mbit' is not a bandwidth"),
    ("netns:", "FORMATION_MATCH_HOSTS='netns:': '' is not a bandwidth"),
])
def test_a_bad_value_is_one_line_before_the_command_runs(value, named, monkeypatch, capsys,
                                                         tmp_path):
    monkeypatch.setenv(zenoh.HOSTS_ENV, value)
    code = main([*ONLINE, "--transport", "zenoh", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(f"error: {named}"), err
    assert not (tmp_path / "out").exists()


def test_namespaces_that_cannot_be_made_are_named(monkeypatch):
    monkeypatch.setenv(zenoh.HOSTS_ENV, "netns")
    monkeypatch.setattr(zenoh, "_namespaces_unavailable", lambda: "making network namespaces "
                                                                 "needs root")
    with pytest.raises(InputError, match=r"FORMATION_MATCH_HOSTS='netns': robots on hosts of "
                                         r"their own need network namespaces, which cannot be "
                                         r"made here \(making network namespaces needs root\)"):
        with zenoh.online_robots():
            pass


@pytest.mark.parametrize("value", [None, "", "loopback"])
def test_the_loopback_is_the_default(value, monkeypatch):
    if value is None:
        monkeypatch.delenv(zenoh.HOSTS_ENV, raising=False)
    else:
        monkeypatch.setenv(zenoh.HOSTS_ENV, value)
    assert zenoh.team_launcher() is launcher.launch_team


@needs_namespaces
def test_an_online_run_on_hosts_with_capped_cables_equals_the_simulator(monkeypatch, tmp_path):
    """Every team of a 2-step online run (each step's matching, stage and fusion) on hosts of
    its own with 1 Mbit/s cables: the same links, steps and reasons as the simulator, the
    robots' traffic across the cables, and no namespace left."""
    teams, rigs = [], []
    start, close = launcher.launch_team, netns.NetnsRig.close

    def spy_launch(team, *a, **kw):
        teams.append((team.name, team.observer, [r.endpoint for r in team.robots]))
        return start(team, *a, **kw)

    def spy_close(rig):
        if rig._made and rig.procs:  # what crossed each cable, and its queueing discipline
            rigs.append((rig.link_bytes(), [rig.qdisc(a, b) for a, b in rig.edges]))
        close(rig)

    monkeypatch.setattr(launcher, "launch_team", spy_launch)
    monkeypatch.setattr(netns.NetnsRig, "close", spy_close)
    assert main([*ONLINE, "--out", str(tmp_path / "sim")]) == 0
    monkeypatch.setenv(zenoh.HOSTS_ENV, "netns:1mbit")
    assert main([*ONLINE, "--transport", "zenoh", "--out", str(tmp_path / "hosts")]) == 0
    for name in ("links.csv", "link_steps.csv"):
        sim = (tmp_path / "sim" / name).read_text().splitlines()
        assert (tmp_path / "hosts" / name).read_text().splitlines() == sim, name
    assert ",deleted," in (tmp_path / "sim" / "links.csv").read_text()  # there were cuts
    # each step's matching, stage and fusion: a team of robots on their own hosts
    names = [name for name, _, _ in teams]
    assert [n for n in names if n.startswith("online-match-")] == \
        ["online-match-0", "online-match-1"]
    assert names.count("resolve") == 2 and names.count("online-fusion") == 2
    for _, observer, endpoints in teams:
        assert observer.startswith("unixsock-stream//")
        assert all(ep.startswith("tcp/10.78.") and ep.endswith(":7447") for ep in endpoints)
    assert len(rigs) == len(teams)
    for crossed, qdiscs in rigs:
        assert crossed and all(b > 0 for b in crossed.values())  # the robots talked over them
        assert all("tbf" in q and "1Mbit" in q for q in qdiscs)
    assert _namespaces(os.getpid()) == []


def _links_team(links_path):
    from zygote_teams import EDGES, FPC

    data = {"kind": "links", "links": str(links_path), "features_per_camera": FPC}
    return launcher.make_team("hosted", EDGES, data, {"round_timeout_s": 20.0}, n=4)


@pytest.fixture
def _zygote_teams(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "tests" / "pipeline" / "team"))


@needs_namespaces
def test_a_failed_team_leaves_no_namespace(tmp_path, _zygote_teams):
    """A robot that fails (its links file is not there): the TeamError naming it, and the
    team's namespaces deleted."""
    team = _links_team(tmp_path / "missing.csv")
    with pytest.raises(TeamError, match=r"robot \d \(tcp/10\.78\.[0-9.]+:7447\) failed with "
                                        r"exit code 2: .*missing\.csv.*no such file"):
        netns.launch_team_on_hosts(team, tmp_path / "team", timeout_s=120)
    assert _namespaces(os.getpid()) == []


CHILD = """
import sys
sys.path.insert(0, {tests!r})
from pathlib import Path
from zygote_teams import EDGES, FPC, LINKS
from pipeline.team.launcher import make_team
from pipeline.team.netns import launch_team_on_hosts

Path({links!r}).write_text(LINKS)
data = {{"kind": "links", "links": {links!r}, "features_per_camera": FPC}}
team = make_team("interrupted", EDGES, data, {{"round_timeout_s": 60.0}}, n=4)
# robot 2 frozen as it starts: the team waits for it far beyond the test's Ctrl-C
launch_team_on_hosts(team, {work!r}, timeout_s=300, kill=(2, "started", 0.0, 120.0),
                     rate="1mbit")
"""


@needs_namespaces
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_ctrl_c_or_sigterm_removes_the_namespaces(tmp_path, sig):
    code = CHILD.format(tests=str(ROOT / "tests" / "pipeline" / "team"),
                        links=str(tmp_path / "in.csv"), work=str(tmp_path / "team"))
    child = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stderr=subprocess.PIPE)
    try:
        end = time.monotonic() + 60
        while not (tmp_path / "team" / "robot2.log").exists() or len(_namespaces(child.pid)) < 4:
            assert time.monotonic() < end and child.poll() is None, "the team did not start"
            time.sleep(0.1)
        time.sleep(1.0)
        child.send_signal(sig)
        _, err = child.communicate(timeout=60)
    finally:
        child.kill()
    if sig == signal.SIGINT:
        assert child.returncode != 0 and b"KeyboardInterrupt" in err
    else:  # the launcher's handler: Terminated, through every clean-up
        assert child.returncode == 128 + signal.SIGTERM, err
    assert _namespaces(child.pid) == []
