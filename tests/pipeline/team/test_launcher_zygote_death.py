"""pipeline.team.launcher.launch_team: a zygote killed while its robots run (they die with it)
stops the team at once with a TeamError naming the zygote, with a zygote of the team's own or
a shared one; the team does not wait for exits that never come until its time limit."""

import contextlib
import os
import signal
import threading
import time
from pathlib import Path

import pytest
from zygote_teams import EDGES, FPC, LINKS, children

from pipeline.errors import TeamError


def _zygote_of(pid: int) -> int | None:
    for child in children(pid):
        with contextlib.suppress(OSError):
            if b"pipeline.team.zygote" in Path(f"/proc/{child}/cmdline").read_bytes():
                return child
    return None


def _kill_zygote_once_its_robots_run(n: int, seen: list) -> None:
    """Stop every robot as soon as the zygote forked them all (they cannot finish), then
    ``kill -9`` the zygote."""
    end = time.monotonic() + 30
    while time.monotonic() < end:
        z = _zygote_of(os.getpid())
        robots = children(z) if z is not None else []
        if len(robots) == n:
            for r in robots:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(r, signal.SIGSTOP)
            os.kill(z, signal.SIGKILL)
            seen.extend([z, *robots])
            return
        time.sleep(0.01)


@pytest.mark.parametrize("shared", [False, True])
def test_a_zygote_killed_mid_team_stops_the_team_at_once(shared, tmp_path):
    from pipeline.team.launcher import launch_team, make_team, shared_zygote

    links = tmp_path / "in.csv"
    links.write_text(LINKS)
    team = make_team("zygote-death", EDGES, {"kind": "links", "links": str(links),
                                             "features_per_camera": FPC}, n=4)
    seen: list = []
    killer = threading.Thread(target=_kill_zygote_once_its_robots_run, args=(4, seen))
    with shared_zygote() if shared else contextlib.nullcontext():
        killer.start()
        t0 = time.monotonic()
        with pytest.raises(TeamError, match=r"zygote .* ended with exit code -9 "
                           r"(while robot \d|before starting every robot)"):
            launch_team(team, tmp_path / "work", timeout_s=30)
        took = time.monotonic() - t0
        killer.join()
    assert seen and took < 10
    time.sleep(0.2)
    assert not [p for p in seen if _alive(p)]


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False
