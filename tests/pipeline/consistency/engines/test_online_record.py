"""The figures of an online step's record (pipeline.consistency.engines.online): its traffic,
rounds and memory are its stage's, the labels of its new links and its weighing's; its cut
old links are the cuts of links that earlier steps made."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from online_streams import camera, project, streams

from pipeline.consistency.engines.online import Frame, OnlineAssociation, simulated_stage
from pipeline.consistency.engines.online_detection import LABEL_BYTES
from pipeline.types import Links


def _spurious_step(weigh: bool):
    """One step of three posed cameras, one feature each: 0 and 1 see X, 2 sees Y, and all
    three are linked (the weighing cuts the two links to camera 2). Returns the record, the
    stats of the stage it ran and the association."""
    X, Y = np.array([0.5, 0.2, 1.0]), np.array([1.5, -0.4, 0.5])
    P = [camera(x) for x in (0.0, 1.0, 2.0)]
    frames = [Frame(i, 1, project(P[i], X if i < 2 else Y)[None], P[i]) for i in range(3)]
    seen = []

    def stage(*args, **kw):
        res = simulated_stage(*args, **kw)
        seen.append(res.stats)
        return res

    oa = OnlineAssociation(window=2, weigh=weigh, stage=stage)
    rec = oa.add_step(frames, Links([0, 0, 1], [0, 0, 0], [1, 2, 2], [0, 0, 0],
                                    [0.9, 0.3, 0.2]))
    (st,) = seen
    return rec, st, oa


@pytest.mark.parametrize("weigh", [True, False])
def test_a_steps_traffic_is_its_stages_its_new_links_labels_and_its_weighings(weigh):
    rec, st, _ = _spurious_step(weigh)
    assert rec["cut_weigh"] == (2 if weigh else 0)
    assert rec["history_bytes"] == 0 and rec["history_rounds"] == 0
    # each new link: one message carrying both ends' labels
    assert rec["messages"] == st["messages"] + 3 + rec["weigh_messages"]
    assert rec["bytes"] == st["bytes"] + 3 * 2 * LABEL_BYTES + rec["weigh_bytes"]
    assert (rec["weigh_messages"] > 0) == weigh


def test_the_weighing_takes_its_rounds_and_memory_into_the_steps():
    rec, st, _ = _spurious_step(True)
    assert rec["weigh_rounds"] == 3
    assert rec["detection_rounds"] == st["detection_rounds"]
    # the weighing follows the detection: the rule's rounds or the weighing's, the longer
    assert rec["resolution_rounds"] == max(st["resolution_rounds"], 3)
    assert rec["rounds"] == rec["detection_rounds"] + rec["resolution_rounds"]
    # every camera of the set holds its three bundles of 128 + 16 * 2 bytes
    assert rec["stage_peak_bytes"] == max(st["max_robot_memory_bytes"], 3 * 160)


@pytest.mark.parametrize("resolution", ["paper", "evidence"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=streams())
def test_cut_old_counts_the_step_s_cuts_of_earlier_links(resolution, data):
    window, hold, stream = data
    oa = OnlineAssociation(window, resolution=resolution, hold=hold)
    for t, (frames, links) in enumerate(stream):
        rec = oa.add_step(frames, links)
        L = oa.links
        now = np.asarray(L.step_cut) == t
        added = np.asarray(L.step_added)
        assert rec["cut"] == int(now.sum())
        assert rec["cut_old"] == int((now & (added < t)).sum())
        assert rec["cut"] - rec["cut_old"] == int((now & (added == t)).sum())


@pytest.mark.parametrize("overturn", [True, False])
def test_the_records_history_check_counts_the_pieces_it_compares(overturn):
    """The record's own check (``robots_check`` off) of a set of two retired pieces: the
    set's two robots compare the pieces' entries (four, one per robot and piece) and names,
    then flood the set's links to rebuild it (``overturn``: its five window and border
    links) or the step's three new links to repair it."""
    from pipeline.consistency.engines.online_history import FLOOD_LINK_BYTES, RETIRED_ENTRY_BYTES

    oa = OnlineAssociation(window=2, resolution="paper", hold=0, robots_check=False,
                           overturn=overturn)
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [0, 1], [2, 3], [0, 0]))
    rec = oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2, 3, 4], [0, 0, 0], [4, 4, 5],
                                                        [0, 0, 0], [0.9, 0.5, 0.7]))
    assert rec["cut_history"] == 1 and len(oa.ret_piece) == 4
    compare = 2 * (4 * RETIRED_ENTRY_BYTES + 2 * LABEL_BYTES)
    flooded = 2 * FLOOD_LINK_BYTES * (5 if overturn else 3)
    assert rec["history_bytes"] == compare + flooded


def test_a_set_above_the_bundle_budget_is_left_to_the_rules_merge(monkeypatch):
    """With ``B = 2`` the three features of the step's set make a large set: the rule's
    stage merges it (``sync`` on its links) and the weighing leaves it alone."""
    from pipeline.consistency import setlists

    monkeypatch.setattr(setlists, "SET_BUNDLE_BYTES", 0)  # B: the least, 2
    rec, st, _ = _spurious_step(True)
    assert st["bundle_budget"] == 2 and st["large_sets"] == 1
    assert rec["weighed_sets"] == 0 and rec["cut_weigh"] == 0
    assert rec["weigh_messages"] == 0 and rec["weigh_bytes"] == 0


def test_the_robots_history_check_reports_its_largest_robot_state(monkeypatch):
    """``peak_bytes`` of the robots' check (engines.history_run) is the largest state any
    of its robots holds at the end, not some robot's."""
    from pipeline.consistency.engines import history_run

    robots = []

    def equip(rb, inputs):
        robots.append(rb)
        return equip_history(rb, inputs)

    equip_history = history_run.equip_history
    monkeypatch.setattr(history_run, "equip_history", equip)
    checks = []

    def stage(*args, **kw):
        res = simulated_stage(*args, **kw)
        checks.append(res.stats.get("history"))
        return res

    oa = OnlineAssociation(window=2, resolution="paper", hold=0, stage=stage)
    oa.add_step([Frame(0, 2), Frame(1, 2)], Links([0, 0], [0, 1], [1, 1], [0, 1]))
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([0, 1], [0, 1], [2, 3], [0, 0]))
    robots.clear()
    oa.add_step([Frame(0, 1), Frame(1, 1)], Links([2, 3, 4], [0, 0, 0], [4, 4, 5],
                                                  [0, 0, 0], [0.9, 0.5, 0.7]))
    sizes = [rb.history.nbytes() for rb in robots]
    assert len(set(sizes)) > 1  # the robots hold states of different sizes
    assert checks[-1]["peak_bytes"] == max(sizes)


def test_retiring_features_that_join_two_pieces_keep_the_smaller_name():
    """Step 0: tracks A = {0, 1} and B = {2, 3}; step 1 extends them (4 to A, 6 to B) and
    joins them (4-6). Step 0 retires at step 2: two pieces, 0 and 1; step 1 retires at step 3:
    4 and 6 join both pieces, which keep the smaller name; only piece 1's two entries (its
    frames' robots 2 and 3) are renamed (``retire_bytes``, eight bytes per renamed entry)."""
    oa = OnlineAssociation(window=2, resolution="paper", hold=0)
    frames = [Frame(i, 1) for i in range(4)]
    oa.add_step(frames, Links([0, 2], [0, 0], [1, 3], [0, 0]))
    oa.add_step(frames, Links([0, 2, 4], [0, 0, 0], [4, 6, 6], [0, 0, 0]))
    oa.add_step(frames, Links([], [], [], []))
    assert oa.piece[:4].tolist() == [0, 0, 1, 1]
    rec = oa.add_step(frames, Links([], [], [], []))
    assert oa.piece[:7].tolist() == [0, 0, 0, 0, 0, -1, 0]
    assert rec["retire_bytes"] == 16
