"""The private folders a command makes in the temporary folder (``fm-team-*`` of a team,
``colmap-read-*`` of a database read, ``online-*`` of an online run, ...) left by a process
killed outright (kill -9, the OOM killer, a test's timeout) are removed by the next folder of
the same kind made on the machine: they piled up in /tmp, a copy of a database each, and
nothing ever removed them. A live process's folders and anyone else's are kept."""

import os
import signal
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

from pipeline.runfolder import make_scratch_folder, scratch_folder

ROOT = Path(__file__).resolve().parents[2]

KILLED = textwrap.dedent("""
    import os, signal, sys
    from pipeline.runfolder import make_scratch_folder
    folder = make_scratch_folder(sys.argv[1])
    (folder / "TEAM.json").write_text("{}")
    print(folder.name, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
""")


def _killed_maker(tmp: Path, prefix: str) -> str:
    done = subprocess.run([sys.executable, "-c", KILLED, prefix], cwd=ROOT, capture_output=True,
                          text=True, timeout=60, env={**os.environ, "TMPDIR": str(tmp)})
    assert done.returncode == -signal.SIGKILL, done.stderr
    return done.stdout.strip()


def test_a_killed_processes_folder_is_removed_by_the_next_of_its_kind(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    dead = _killed_maker(tmp_path, "fm-team-")
    other = _killed_maker(tmp_path, "colmap-read-")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([dead, other])
    with scratch_folder("fm-team-") as mine:
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted([other, Path(mine).name])
    assert sorted(p.name for p in tmp_path.iterdir()) == [other]  # another kind's: its own turn
    make_scratch_folder("colmap-read-").rmdir()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_live_and_foreign_folders_are_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    live = make_scratch_folder("fm-team-")  # this process's: alive
    dead = _killed_maker(tmp_path, "fm-team-")
    pid, start, digest, rand = dead.removeprefix("fm-team-").split("-")
    theirs = ["fm-team-abcd1234",  # a name of tempfile's, of no process
              f"fm-team-{pid}-{start}-{'0' * 12}-{rand}",  # a digest of no process
              f"fm-team-{pid}-{int(start) + 1}-{digest}-{rand}"]  # the digest of another
    for name in theirs:
        (tmp_path / name).mkdir()
    (tmp_path / "link").symlink_to(tmp_path / theirs[0])
    with scratch_folder("fm-team-") as mine:
        kept = sorted(p.name for p in tmp_path.iterdir())
    assert kept == sorted([live.name, Path(mine).name, *theirs, "link"])
    assert not (tmp_path / dead).exists()


def test_a_team_killed_with_its_launcher_is_removed_by_the_next_team(tmp_path):
    """kill -9 of a process running a team over Zenoh: its fm-team-* is left (it cannot clean
    up), and the next team launched on the machine removes it."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    (tmp_path / "in.csv").write_text("cam_i,feat_i,cam_j,feat_j\n0,0,1,0\n1,0,2,0\n0,1,2,0\n")
    script = textwrap.dedent(f"""
        import os, signal, sys
        import pipeline.team.launcher as launcher
        data = {{"kind": "links", "links": {str(tmp_path / "in.csv")!r},
                 "features_per_camera": [2, 1, 1]}}
        team = launcher.make_team("killed", [[0, 1], [1, 2], [0, 2]], data, n=3)
        if sys.argv[1] == "kill":
            write = launcher.write_team

            def written_then_killed(*args):
                out = write(*args)
                os.kill(os.getpid(), signal.SIGKILL)

            launcher.write_team = written_then_killed
        launcher.launch_team(team, timeout_s=60)
    """)
    env = {**os.environ, "TMPDIR": str(tmp)}
    killed = subprocess.run([sys.executable, "-c", script, "kill"], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=60)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert [p.name.startswith("fm-team-") for p in tmp.iterdir()] == [True]
    subprocess.run([sys.executable, "-c", script, "run"], cwd=ROOT, env=env, check=True,
                   capture_output=True, timeout=60)
    assert sorted(p.name for p in tmp.iterdir()) == []
