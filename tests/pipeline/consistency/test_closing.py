"""The closing phase of the fault-tolerant protocol: a crash at any round of the run is handled.

A robot may crash at any network round: before, during or after any detection or resolution,
and after its last detection (when nobody expects anything from it any more). Rule
(:mod:`pipeline.consistency.reliable`, "Closing round"): a robot that crashed before it
acknowledged every ``closing`` message of its linked neighbours has all its links to the
survivors cut as ``robot-lost``; one that crashed after that is reported as
``crashed_after_close`` and its links, confirmed at the close, stay kept.
"""

import numpy as np
from consistency_graphs import instances, random_instance
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.association import AssociationGraph, count_conflicts
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.centralized import is_conflict_free
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.faults import FaultConfig
from pipeline.transport.simulated import NetworkOptions
from pipeline.types import Links


def protocol(delay: int) -> ProtocolOptions:
    """The robots' protocol with their timers set for the delay, as the command line does."""
    p = FaultConfig(delay_rounds=delay).protocol_options() or ProtocolOptions()
    p.reliable = True
    return p


def run(fpc, edges, links, crashes=None, p=0.0, delay=0, seed=0):
    opts = NetworkOptions(drop_probability=p, delay_rounds=delay, crash_at=dict(crashes or {}),
                          seed=seed)
    return resolve_conflicts(fpc, edges, links, opts, protocol=protocol(delay), resolution="paper")


def check_end_state(fpc, links: Links, res, delay: int = 0) -> None:
    """What a run with crashes must give, whatever the crash rounds (module docstring)."""
    L = len(links)
    f = res.stats["faults"]
    surv = res.stats["survivors"]
    # every input link comes back exactly once, kept or cut with a reason
    assert res.deleted.shape == res.reason.shape == (L,)
    assert set(res.reason[res.deleted].tolist()) <= {"resolution", "robot-lost"}
    assert (res.reason[~res.deleted] == "").all()
    # the loop of the reliable protocol always ends with a closing phase that lost nobody
    close = f["close_round"]
    assert close is not None and not res.stats["per_iteration"][-1].get("repeated")
    both = surv[links.cam_i] & surv[links.cam_j]
    assert is_conflict_free(fpc, links.subset(~res.deleted & both))
    assert res.stats["asymmetric_links"] == 0
    after_close = f["crashed_after_close"]
    for k, r in f["crashed"].items():
        to_survivor = ((links.cam_i == k) & surv[links.cam_j]) | ((links.cam_j == k) & surv[links.cam_i])
        if k not in after_close:
            # noticed: every link it shared with a survivor is cut, with a reason
            assert res.deleted[to_survivor].all(), (k, r, close)
            assert set(res.reason[to_survivor].tolist()) <= {"robot-lost", "resolution"}
        elif (~res.deleted[to_survivor]).any():
            # kept links only if it was alive to acknowledge the closing messages
            assert r > close + 1 + delay, (k, r, close)
    # robots dead before the close never count as having confirmed it
    assert all(r > close for r in after_close.values())
    # the survivors and the robots that confirmed the close hold a conflict-free association
    held = surv.copy()
    held[list(after_close)] = True
    assert is_conflict_free(fpc, links.subset(~res.deleted & held[links.cam_i] & held[links.cam_j]))


@st.composite
def crash_runs(draw):
    """An instance, a fault setting, and 1–3 crashes at rounds anywhere in the run."""
    fpc, edges, links = draw(instances(max_n=7, max_feat=5))
    p = draw(st.sampled_from([0.0, 0.0, 0.2]))
    delay = draw(st.sampled_from([0, 0, 2]))
    seed = draw(st.integers(0, 2**16))
    # the same run without a crash: its length is the range of the crash rounds
    total = run(fpc, edges, links, p=p, delay=delay, seed=seed).stats["faults"]["rounds"]
    crashes = draw(st.dictionaries(st.integers(0, len(fpc) - 1), st.integers(0, total + 2),
                                   min_size=1, max_size=3))
    return fpc, edges, links, crashes, p, delay, seed


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(crash_runs())
def test_a_crash_at_any_round_of_the_run_is_handled(case):
    fpc, edges, links, crashes, p, delay, seed = case
    res = run(fpc, edges, links, crashes, p, delay, seed)
    check_end_state(fpc, links, res, delay)


def _instance():
    return random_instance(np.random.default_rng(3), 6, 5, 0.6, 0.9)


def test_crash_after_the_last_detection_is_noticed_by_the_close():
    """The case the closing phase exists for: each robot crashes after the last detection
    ended (nothing more is expected from it), before the closing messages reach it."""
    fpc, edges, links = _instance()
    base = run(fpc, edges, links)
    last = base.stats["per_iteration"][-1]
    close = base.stats["faults"]["close_round"]
    assert last["start_round"] + last["detection_rounds"] == close  # closing follows at once
    for k in range(len(fpc)):
        touch = (links.cam_i == k) | (links.cam_j == k)
        if not touch.any():
            continue
        res = run(fpc, edges, links, {k: close + 1})
        assert res.stats["faults"]["crashed"] == {k: close + 1}
        assert res.stats["faults"]["robots_lost"].get(k), k
        assert res.deleted[touch].all() and set(res.reason[touch].tolist()) <= {"robot-lost",
                                                                                "resolution"}
        assert res.stats["faults"]["repeated_detections"] >= 1
        check_end_state(fpc, links, res)


def test_crash_after_confirming_the_close_keeps_its_links_and_says_so():
    fpc, edges, links = _instance()
    base = run(fpc, edges, links)
    end = base.stats["faults"]["rounds"]
    k = int(links.cam_i[0])
    res = run(fpc, edges, links, {k: end})  # dies in the very round the stage ends
    f = res.stats["faults"]
    assert f["crashed"] == {k: end} and f["crashed_after_close"] == {k: end}
    np.testing.assert_array_equal(res.deleted, base.deleted)
    check_end_state(fpc, links, res)


def test_closing_on_a_lossless_network_costs_one_round_trip_and_cuts_nothing():
    fpc, edges, links = _instance()
    paper = resolve_conflicts(fpc, edges, links, resolution="paper")
    res = run(fpc, edges, links)
    np.testing.assert_array_equal(res.deleted, paper.deleted)
    assert res.stats["closing_rounds"] == 2 and "closing_rounds" not in paper.stats
    # one closing message per robot and linked neighbour, each acknowledged
    kept = res.kept()
    pairs = {(min(a, b), max(a, b)) for a, b in zip(kept.cam_i.tolist(), kept.cam_j.tolist(),
                                                       strict=True)}
    assert res.stats["messages_by_kind"]["closing"] == 2 * len(pairs)
    assert res.stats["faults"]["retransmissions"] == 0


def test_five_crashes_leave_links_only_between_crashed_robots_and_flag_them():
    """Links between two robots that crashed early are held by no survivor: nobody can cut
    them; the run reports them as left (the command flags a result they make conflictive)."""
    fpc, edges, links = random_instance(np.random.default_rng(0), 6, 6, 1.0, 0.8)
    res = run(fpc, edges, links, {k: k for k in range(1, 6)})
    check_end_state(fpc, links, res)
    surv = res.stats["survivors"]
    assert surv.tolist() == [True] + [False] * 5
    dead_dead = ~surv[links.cam_i] & ~surv[links.cam_j]
    assert (~res.deleted[dead_dead]).any()
    assert count_conflicts(AssociationGraph(fpc, res.kept())).conflictive_sets > 0
