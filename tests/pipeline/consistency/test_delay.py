"""The consistency stage on a network that delivers every message ``delay_rounds`` late.

Delay alone costs rounds, never a link: the lockstep detection is exact and Alg. 1 is
insensitive to delivery delays (:mod:`pipeline.consistency.reliable`). With crashes, a message
may be in flight over a link whose sender or receiver crashes before it arrives; the protocol
must still end with the guarantees of the closing phase (:mod:`test_closing`).
"""

import numpy as np
import pytest
from consistency_graphs import instances, random_instance
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_closing import check_end_state, protocol, run
from test_fault_tolerance import exact

from pipeline.commgraph import comm_edges_for
from pipeline.consistency import resolve_conflicts
from pipeline.consistency.engines import driver as engine
from pipeline.consistency.engines.driver import detect_once
from pipeline.transport.simulated import Network, NetworkOptions, recurrent_topology

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FAST
@given(instances(), st.integers(1, 6), st.sampled_from([0.0, 0.3]), st.integers(0, 2**16))
def test_lockstep_detection_is_exact_under_delay(inst, delay, p, seed):
    fpc, edges, links = inst
    lossless = detect_once(fpc, links, edges).robots
    robots = detect_once(fpc, links, edges, NetworkOptions(drop_probability=p, delay_rounds=delay,
                                                            seed=seed),
                         protocol(delay), max_rounds=100_000).robots
    assert exact(fpc, links, robots)
    assert [rb.t_stop for rb in robots] == [rb.t_stop for rb in lossless]  # Cor. 3.6


@FAST
@given(instances(), st.integers(1, 8))
def test_delay_alone_costs_rounds_not_links(inst, delay):
    fpc, edges, links = inst
    paper = resolve_conflicts(fpc, edges, links, resolution="paper")
    res = run(fpc, edges, links, delay=delay)
    np.testing.assert_array_equal(res.deleted, paper.deleted)
    f = res.stats["faults"]
    assert not f["robots_lost"] and f["retransmissions"] == 0  # timers set for the latency
    assert f["rounds"] >= (delay + 1) * (paper.stats["detection_rounds"] - 1)


@pytest.mark.parametrize("delay", [1, 5, 19])
def test_default_timers_under_delay_retransmit_but_lose_nobody(delay):
    """Robots whose timers ignore the latency resend every unacknowledged message each round
    but, with ``T`` above the round trip, declare nobody lost and cut the same links."""
    from pipeline.consistency.protocols import ProtocolOptions

    fpc, edges, links = random_instance(np.random.default_rng(2), 7, 5, 0.6, 0.9)
    paper = resolve_conflicts(fpc, edges, links, resolution="paper")
    res = resolve_conflicts(fpc, edges, links, NetworkOptions(delay_rounds=delay),
                            protocol=ProtocolOptions(reliable=True), resolution="paper")
    np.testing.assert_array_equal(res.deleted, paper.deleted)
    assert not res.stats["faults"]["robots_lost"]
    assert res.stats["faults"]["retransmissions"] > 0


@st.composite
def delayed_crash_runs(draw):
    fpc, edges, links = draw(instances(max_n=7, max_feat=5))
    delay = draw(st.integers(1, 5))
    p = draw(st.sampled_from([0.0, 0.0, 0.2]))
    switching = draw(st.booleans())
    seed = draw(st.integers(0, 2**16))
    total = run(fpc, edges, links, p=p, delay=delay, seed=seed).stats["faults"]["rounds"]
    crashes = draw(st.dictionaries(st.integers(0, len(fpc) - 1), st.integers(0, total + 2),
                                   min_size=1, max_size=2))
    return fpc, edges, links, crashes, p, delay, switching, seed


class RecordingNetwork(Network):
    """The simulated network, remembered so the test can read its in-flight counters."""

    made: list = []

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        RecordingNetwork.made.append(self)


@pytest.fixture
def recorded(monkeypatch):
    RecordingNetwork.made = []
    monkeypatch.setattr(engine, "Network", RecordingNetwork)
    return RecordingNetwork.made


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(delayed_crash_runs())
def test_delayed_messages_with_crashes_and_switching_links_end_correctly(recorded, case):
    fpc, edges, links, crashes, p, delay, switching, seed = case
    e = comm_edges_for(fpc, links, edges)
    topo = recurrent_topology(e, 0.5, 3, seed) if switching else None
    opts = NetworkOptions(drop_probability=p, delay_rounds=delay, crash_at=crashes,
                          topology=topo, seed=seed)
    res = resolve_conflicts(fpc, edges, links, opts, protocol=protocol(delay), resolution="paper")
    check_end_state(fpc, links, res, delay)


def test_messages_in_flight_when_their_sender_or_receiver_crashes(recorded):
    """Every crash round of every robot, delay 3: the runs include messages that were in
    flight over a link whose receiver crashed (lost) or whose sender crashed (delivered
    late, into a later phase), and every run ends with the guarantees of the close."""
    fpc, edges, links = random_instance(np.random.default_rng(4), 4, 4, 0.7, 0.9)
    total = run(fpc, edges, links, delay=3).stats["faults"]["rounds"]
    lost_in_flight = delivered_late = 0
    for k in range(len(fpc)):
        for r in range(0, total + 2, 3):
            recorded.clear()
            res = run(fpc, edges, links, {k: r}, delay=3)
            check_end_state(fpc, links, res, 3)
            net = recorded[0]
            lost_in_flight += net.lost_in_flight
            delivered_late += net.delivered_after_sender_crash
    assert lost_in_flight > 0 and delivered_late > 0
