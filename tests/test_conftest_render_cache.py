"""The test session's folder of rendered views (``formation-match-render-cache-*``, made by
tests/conftest.py) was removed only when the session ended normally: a session killed (a
timeout, kill -9) left it in the temporary folder, with its renderings, and they piled up. The next session now
removes those of sessions no longer alive."""

import os
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: tests/conftest.py's session start, then (with "kill") a death by kill -9, else its end
SESSION = ("import os, signal, sys; sys.path.insert(0, 'tests'); import conftest; "
           "conftest.pytest_configure(None); print(os.environ[conftest.ENV], flush=True); "
           "os.kill(os.getpid(), signal.SIGKILL) if sys.argv[1] == 'kill' else "
           "conftest.pytest_unconfigure(None)")


def test_a_killed_sessions_render_cache_is_removed_by_the_next_session(tmp_path):
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    env.pop("FORMATION_MATCH_CACHE", None)
    killed = subprocess.run([sys.executable, "-c", SESSION, "kill"], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=60)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    left = Path(killed.stdout.strip())
    assert left.parent == tmp_path and left.is_dir()
    subprocess.run([sys.executable, "-c", SESSION, "end"], cwd=ROOT, env=env, check=True,
                   capture_output=True, timeout=60)
    assert sorted(p.name for p in tmp_path.iterdir()) == []
