"""pipeline.team.launcher.launch_team and the signals that reach it while its team starts.

- A SIGTERM once the team's folder was written and before the launcher's handlers were set
  killed the process with ``fm-team-*`` left in the temporary folder (the handlers came after
  the folder, its TEAM.json and the observer).
- A Ctrl-C while the zygote was being forked ran its handler within Python's hooks around the
  fork, which drop the exception: the team ran on to its end as if nothing had happened."""

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

#: a team of three robots over links, launched in a process whose temporary folder is the
#: first argument; PATCH (below) sends the signal
SCRIPT = textwrap.dedent("""
    import os, signal, sys
    import pipeline.team.launcher as launcher
    links = os.path.join(sys.argv[1], "..", "in.csv")
    data = {"kind": "links", "links": links, "features_per_camera": [2, 1, 1]}
    team = launcher.make_team("signals", [[0, 1], [1, 2], [0, 2]], data, n=3)
    PATCH
    try:
        launcher.launch_team(team, timeout_s=60)
    except KeyboardInterrupt:
        print("interrupted")
    else:
        print("finished")
""")

AFTER_WRITE = """
write = launcher.write_team
def written_then_killed(*args):
    out = write(*args)
    os.kill(os.getpid(), signal.SIGTERM)
    return out
launcher.write_team = written_then_killed
"""

AT_FORK = """
sent = []
def ctrl_c_within_the_fork_hook():
    if not sent:
        sent.append(1)
        os.kill(os.getpid(), signal.SIGINT)
os.register_at_fork(after_in_parent=ctrl_c_within_the_fork_hook)
"""


def _launch(tmp_path, patch: str) -> tuple[subprocess.CompletedProcess, Path]:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,1,2,0\n")
    code = SCRIPT.replace("PATCH", patch)
    done = subprocess.run([sys.executable, "-c", code, str(tmp)], cwd=ROOT,
                          env={**os.environ, "TMPDIR": str(tmp)}, capture_output=True,
                          text=True, timeout=60)
    return done, tmp


def test_a_sigterm_before_the_team_starts_leaves_no_folder(tmp_path):
    done, tmp = _launch(tmp_path, AFTER_WRITE)
    assert done.returncode == 128 + signal.SIGTERM, done.stderr
    assert sorted(p.name for p in tmp.iterdir()) == []


def test_a_ctrl_c_within_the_fork_of_the_zygote_stops_the_team(tmp_path):
    done, tmp = _launch(tmp_path, AT_FORK)
    assert (done.returncode, done.stdout) == (0, "interrupted\n"), done.stderr
    assert sorted(p.name for p in tmp.iterdir()) == []
