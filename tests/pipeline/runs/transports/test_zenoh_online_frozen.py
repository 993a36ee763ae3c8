"""An online step's team over Zenoh with a robot process FROZEN (``kill -STOP``, then
``kill -CONT`` after longer than the round timeout: a host suspended or cut off for a
while). Its process does not end, so the team is not stopped at once: its neighbours write
it off, and the step must still start the team again as for a lost process, never stop the
run."""

import copy

import numpy as np
import pytest
from frozen_robots import freezing

import pipeline.runs.transports.zenoh as zenoh
from pipeline.runs.online import _fuse_changed, associate_online
from pipeline.runs.transports import get_transport
from pipeline.team.launcher import team_round_timeout

ROUND_TIMEOUT_S = 2.0
STOP_S = 8.0  # past the round timeout: the neighbours write the frozen robot off


def _step0(transport="sim"):
    from data_synth.motion import render_motion
    from pipeline.progress import StageTimer

    seq = render_motion("ring", 0, 1, (160, 120), n_robots=4, window=2)
    run = associate_online(seq.flat.views, seq.n_robots, seq.step_edges, 2, "evidence",
                           StageTimer(verbose=False), max_features=120, fusion=False,
                           transport=transport)
    return run.online, seq.flat.views, run.features


@pytest.fixture(scope="module")
def one_step():
    """Step 0 of four robots on a ring, on the simulator: its online record, views and
    features."""
    return _step0()


def test_a_fusion_robot_frozen_is_written_off_and_the_fusion_started_again(one_step):
    oa, views, features = one_step
    sim = get_transport("sim").load().online_fusion
    want_oa, got_oa = copy.deepcopy(oa), copy.deepcopy(oa)
    want = _fuse_changed(want_oa, views, features, sim)
    with team_round_timeout(ROUND_TIMEOUT_S):
        got = _fuse_changed(got_oa, views, features,
                            freezing(zenoh.online_fusion, {0}, 1, STOP_S))
    # it stopped the run before ("the fusion team's detection cut link ...: the links
    # handed to fusion must be conflict-free"): the frozen robot's neighbours had cut its
    # links robot-lost in their naming of the tracks
    # the frozen frame only: resumed, it wrote off the neighbours that had ended without it,
    # which are not lost (they were named too: [[0, 1, 2]])
    assert got["frames_lost"] == [[1]] and got["frames_left_out"] == []
    assert (got["cut"], got["tracks"]) == (want["cut"], want["tracks"])
    assert np.array_equal(got_oa.links.kept, want_oa.links.kept)
    assert np.array_equal(got_oa.links.reason, want_oa.links.reason)


def test_a_stage_robot_frozen_while_the_sets_are_solved_at_their_roots(one_step, monkeypatch):
    oa, _, _ = one_step
    monkeypatch.setattr(zenoh, "online_stage",
                        freezing(zenoh.online_stage, {0}, 1, STOP_S, status="roots"))
    with team_round_timeout(ROUND_TIMEOUT_S):
        got, _, _ = _step0("zenoh")
    # it stopped the run before: its neighbours failed ('a robot was lost while the sets were
    # solved at their roots'), a robot error that ended the team with a TeamError
    rec = got.steps[0]
    assert rec["stage_attempts"] == 2 and rec["images_lost"] == [[1]]
    assert rec["cut_lost"] == 0
    for a in ("kept", "reason", "step_cut"):
        assert np.array_equal(getattr(got.links, a), getattr(oa.links, a)), a
