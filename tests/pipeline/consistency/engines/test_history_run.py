"""The history check run by the stage's robots (pipeline.consistency.engines.history_run):
the same cuts, reasons and names as the online record's own check, for every rule."""

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from online_streams import posed_streams, streams

from pipeline.consistency.engines.online import Frame, OnlineAssociation
from pipeline.types import Links


def _both(window, hold, stream, resolution):
    runs = []
    for robots in (True, False):
        oa = OnlineAssociation(window, resolution=resolution, hold=hold, robots_check=robots)
        runs.append((oa, [oa.add_step(frames, links) for frames, links in stream]))
    return runs


@pytest.mark.parametrize("resolution", ["paper", "evidence", "sync"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams(max_robots=5, max_steps=8, max_m=5))
def test_the_robots_check_cuts_and_names_as_the_record(resolution, data):
    """Every step: the same links kept, cut with the same reason at the same step, and the
    same set names afterwards (the robots' cuts are applied, then every set renamed)."""
    window, hold, stream = data
    (a, ra), (b, rb) = _both(window, hold, stream, resolution)
    for name in ("kept", "reason", "step_cut"):
        assert getattr(a.links, name).tolist() == getattr(b.links, name).tolist(), name
    assert a.label.tolist() == b.label.tolist()
    assert [r["cut_history"] for r in ra] == [r["cut_history"] for r in rb]
    assert a.is_conflict_free()
    event(f"history cuts {sum(r['cut_history'] for r in ra) > 0}")


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=posed_streams(max_robots=4, max_steps=6))
def test_the_robots_check_after_the_weighing_cuts_as_the_record(data):
    """With poses the evidence rule's weighing cuts too (its robots at the roots): the check
    sees the links they kept, as the record's does."""
    window, hold, stream = data
    (a, _), (b, _) = _both(window, hold, stream, "evidence")
    for name in ("kept", "reason", "step_cut"):
        assert getattr(a.links, name).tolist() == getattr(b.links, name).tolist(), name


def _chain_stream(k: int, q_old, q_new):
    """Three steps: frame Z (robot 0, image 0), then X and Y (robots 1, 2; images 1, 2) with
    ``x_i - z_i - y_i``; Z retires (window 2, hold 0): piece ``i`` holds ``z_i`` and a
    history link joins ``x_i = y_i``. Then R (robot 0, image 3) links ``r_i - x_i`` and
    ``y_i - r_{i+1}``: one set ``r_0 - x_0 = y_0 - r_1 - x_1 = ... - r_k``, R most often, so
    the paper rule's components from each ``r_i`` meet at the history links and cut them;
    after the rule the check's set still holds R ``k + 1`` times, ``3 k`` links long."""
    i = list(range(k))
    return [([Frame(0, k)], Links([], [], [], [])),
            ([Frame(1, k), Frame(2, k)], Links([0] * 2 * k, i * 2, [1] * k + [2] * k, i * 2,
                                               q_old)),
            ([Frame(0, k + 1)], Links([1] * k + [2] * k, i * 2, [3] * 2 * k,
                                      i + [j + 1 for j in i], q_new))]


@pytest.mark.parametrize("resolution", ["paper", "paper-labels"])
def test_a_long_chain_of_pieces_through_three_frames_is_checked(resolution):
    """Three frames and 10 pieces: the label flooding of the check crosses 30 links and the
    flag it reveals floods back, past the 3 n + 6 = 15 rounds the simulator allowed (it
    stopped with 'history names did not end within 15 rounds')."""
    k = 10
    stream = _chain_stream(k, np.full(2 * k, 0.9), np.full(2 * k, 0.5))
    (a, ra), (b, rb) = _both(2, 0, stream, resolution)
    assert ra[-1]["history_rounds"] > 3 * 3 + 6
    assert ra[-1]["cut_history"] == rb[-1]["cut_history"] > 0
    for name in ("kept", "reason", "step_cut"):
        assert getattr(a.links, name).tolist() == getattr(b.links, name).tolist(), name
    assert a.is_conflict_free()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(k=st.integers(1, 30), resolution=st.sampled_from(["paper", "paper-labels", "evidence"]),
       seed=st.integers(0, 2**31 - 1))
def test_long_chains_of_pieces_cut_as_the_record(k, resolution, seed):
    """Chains of up to 30 pieces through three frames, random qualities: the robots' check
    ends (its phase 1 floods over features, not frames) and cuts as the record's."""
    rng = np.random.default_rng(seed)
    stream = _chain_stream(k, rng.uniform(0.05, 1.0, 2 * k), rng.uniform(0.05, 1.0, 2 * k))
    (a, ra), (b, rb) = _both(2, 0, stream, resolution)
    for name in ("kept", "reason", "step_cut"):
        assert getattr(a.links, name).tolist() == getattr(b.links, name).tolist(), name
    assert a.is_conflict_free()
    event(f"history cuts {ra[-1]['cut_history'] > 0}")
