"""pipeline.team.launcher.die_with_parent: a robot whose zygote died before the robot asked for
the death signal (a fork the loaded machine ran late: the launcher killed with ``kill -9`` just
after its zygote forked a robot) ends at once instead of living on as an orphan robot."""

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

#: the zygote, made to die right after its first fork, and its robot made to ask for the
#: death signal only once the zygote is gone (the order a loaded machine may run them in)
ZYGOTE = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    import pipeline.team.launcher as launcher
    from pipeline.team import zygote
    marks = Path(sys.argv[3])
    me, asked = os.getpid(), launcher.die_with_parent

    def late(*args):
        while os.getppid() == me:
            time.sleep(0.01)
        asked(*args)

    launcher.die_with_parent = late
    fork = os.fork

    def fork_then_die():
        pid = fork()
        if pid:
            (marks / "robot").write_text(str(pid))
            os._exit(0)
        return pid

    os.fork = fork_then_die
    zygote.main(sys.argv[1:3])
""")


def _running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def test_a_robot_whose_zygote_died_before_it_asked_ends_at_once(tmp_path):
    from pipeline.team.launcher import make_team
    from pipeline.team.teamfile import write_team

    (tmp_path / "in.csv").write_text("0,0,1,0\n")
    team = make_team("orphan", [[0, 1]], {"kind": "links", "links": str(tmp_path / "in.csv"),
                                          "features_per_camera": [1, 1]}, n=2)
    path = write_team(tmp_path / "TEAM.json", team)
    subprocess.run([sys.executable, "-c", ZYGOTE, str(path), str(tmp_path), str(tmp_path)],
                   cwd=ROOT, check=True, timeout=60)
    robot = int((tmp_path / "robot").read_text())
    t0 = time.monotonic()
    while _running(robot) and time.monotonic() - t0 < 15:
        time.sleep(0.05)
    orphan = _running(robot)
    if orphan:
        os.kill(robot, 9)
    assert not orphan, (tmp_path / "robot0.log").read_text()


def test_a_child_whose_parent_lives_goes_on():
    code = ("import os\nfrom pipeline.team.launcher import die_with_parent\n"
            "die_with_parent(os.getppid())\nprint('went on')\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, check=True, timeout=60)
    assert out.stdout == "went on\n"
