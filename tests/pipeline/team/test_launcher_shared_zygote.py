"""pipeline.team.launcher.shared_zygote: the teams a job starts one after another fork their
robots from one zygote (imported once), with the same results as a zygote per team; a team
that ends, well or not, leaves none of its robots behind, and the zygote ends with the block."""

import os
import time

import numpy as np
import pytest
from zygote_teams import EDGES, FPC, LINKS, children

from pipeline.errors import TeamError


@pytest.fixture()
def links(tmp_path):
    p = tmp_path / "in.csv"
    p.write_text(LINKS)
    return p


def _resolve(links, work):
    from pipeline.runs.transports.zenoh import resolve_links_file

    res = resolve_links_file(links, FPC, EDGES, workdir=work)
    return res.deleted.copy(), res.stats["team"]


def test_teams_in_one_block_fork_from_one_zygote_with_the_same_results(links, tmp_path):
    from pipeline.team.launcher import shared_zygote

    alone, _ = _resolve(links, tmp_path / "alone")
    with shared_zygote() as zygote:
        first, _ = _resolve(links, tmp_path / "first")
        pid = zygote.proc.pid
        second, summary = _resolve(links, tmp_path / "second")
        assert zygote.proc.pid == pid and zygote.count == 2
        assert children(pid) == []  # each team's robots ended with it
    np.testing.assert_array_equal(first, alone)
    np.testing.assert_array_equal(second, alone)
    assert alone.any()  # the rule cut something: the robots talked
    assert all(r.get("handshake_s") is not None for r in summary["robots"].values())


def test_the_zygote_and_its_group_end_with_the_block(links, tmp_path):
    from pipeline.team.launcher import shared_zygote

    with shared_zygote() as zygote:
        _resolve(links, tmp_path / "a")
        proc = zygote.proc
    assert proc.poll() is not None
    with pytest.raises(ProcessLookupError):
        os.killpg(proc.pid, 0)


def test_a_team_stopped_early_leaves_no_robot_and_the_next_team_runs(links, tmp_path):
    """A team stopped at its time limit while the zygote may still be forking it: robots
    forked after the stop are killed on sight; the zygote serves the next team."""
    from pipeline.team.launcher import launch_team, make_team, shared_zygote

    n = 6
    data = {"kind": "links", "links": str(links), "features_per_camera": FPC + [1] * (n - 4)}
    team = make_team("stopped", [[i, (i + 1) % n] for i in range(n)], data, n=n)
    with shared_zygote() as zygote:
        _resolve(links, tmp_path / "warm")  # the zygote has imported: the stop lands mid-fork
        with pytest.raises(TeamError, match="did not end within"):
            launch_team(team, tmp_path / "stopped", timeout_s=0.01)
        t0 = time.monotonic()
        while children(zygote.proc.pid) and time.monotonic() - t0 < 10:
            time.sleep(0.05)
        assert children(zygote.proc.pid) == []
        again, _ = _resolve(links, tmp_path / "again")
    assert again.any()


def test_a_zygote_that_died_is_started_again(links, tmp_path):
    from pipeline.team.launcher import shared_zygote

    with shared_zygote() as zygote:
        before, _ = _resolve(links, tmp_path / "a")
        zygote.proc.kill()
        zygote.proc.wait(timeout=10)
        after, _ = _resolve(links, tmp_path / "b")
        assert zygote.proc.poll() is None
    np.testing.assert_array_equal(before, after)
