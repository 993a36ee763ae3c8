"""pipeline.team.launcher.SharedZygote: a robot whose ``pid`` line is being read while its
team ends is either among the team's robots the launcher kills or killed on sight; never
left running beside the next team."""

import io
import subprocess
import sys
import threading
import time

from pipeline.team import launcher


def test_a_pid_line_read_as_the_team_ends_is_killed(monkeypatch):
    zygote = launcher.SharedZygote()
    procs, codes, cv, gone = {}, {}, threading.Condition(), threading.Event()
    zygote.teams["1"] = (procs, codes, cv, gone, None)
    robot = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    noted = launcher._note_robot

    def slow_note(*args):  # the reader thread is descheduled between its check and its note
        time.sleep(0.5)
        noted(*args)

    monkeypatch.setattr(launcher, "_note_robot", slow_note)
    reader = threading.Thread(target=zygote._read,
                              args=(None, io.BytesIO(f"pid 1 0 {robot.pid}\n".encode())))
    try:
        reader.start()
        time.sleep(0.2)
        # what launch_team does as the team ends: no more robots of it, then kill those known
        zygote.end_team("1")
        for p in list(procs.values()):
            p.kill()
        reader.join(5)
        assert robot.wait(timeout=3) == -9
    finally:
        robot.kill()
        robot.wait()
        zygote.close()
