"""pipeline.team.launcher.SharedZygote keeps its zygote's standard error in a file without a
name: a launcher killed (kill -9, or a SIGTERM between teams) leaves nothing in the temporary
folder, and the error of a zygote that died is still named."""

import os
import subprocess
import sys
import textwrap

import pytest

from pipeline.errors import TeamError

LINKS = "cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,1,2,0\n"
EDGES = [[0, 1], [1, 2], [0, 2]]


def test_a_killed_launcher_leaves_no_folder_of_its_zygote(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    (tmp_path / "in.csv").write_text(LINKS)
    script = textwrap.dedent(f"""
        import os, signal
        from pipeline.team.launcher import launch_team, make_team, shared_zygote
        data = {{"kind": "links", "links": {str(tmp_path / "in.csv")!r},
                 "features_per_camera": [2, 1, 1]}}
        with shared_zygote():
            launch_team(make_team("leftovers", {EDGES}, data, n=3), timeout_s=60)
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    done = subprocess.run([sys.executable, "-c", script], env={**os.environ, "TMPDIR": str(tmp)},
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == -9, done.stderr
    assert sorted(p.name for p in tmp.iterdir() if p.name.startswith("fm-zygote-")) == []


def test_the_error_of_a_shared_zygote_that_died_is_named(tmp_path, monkeypatch):
    from pipeline.team import launcher

    (tmp_path / "in.csv").write_text(LINKS)
    data = {"kind": "links", "links": str(tmp_path / "in.csv"), "features_per_camera": [2, 1, 1]}
    write = launcher.write_team

    def broken(path, team):
        out = write(path, team)
        out.write_text("{not json")
        return out

    monkeypatch.setattr(launcher, "write_team", broken)
    with launcher.shared_zygote(), \
            pytest.raises(TeamError, match=r"zygote .* before starting every robot.*not valid JSON"):
        launcher.launch_team(launcher.make_team("broken", EDGES, data, n=3), tmp_path / "w",
                             timeout_s=60)
