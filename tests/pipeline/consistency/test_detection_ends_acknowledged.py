"""A fault-tolerant detection ends only when every robot's messages are acknowledged
(reliable.py: done = stopped, every linked neighbour's ``final`` in, every message acked), so
no blocks of it are left to arrive in the detection that may follow it."""

from consistency_graphs import instances
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.consistency.engines.driver import detect_once
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.transport.simulated import NetworkOptions


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances(), st.sampled_from([0.1, 0.3, 0.5]), st.integers(0, 2**16))
def test_a_detection_under_loss_ends_with_every_message_acknowledged(inst, p, seed):
    fpc, edges, links = inst
    det = detect_once(fpc, links, edges, NetworkOptions(drop_probability=p, seed=seed),
                      ProtocolOptions(reliable=True), max_rounds=100_000, engine="per-robot")
    for rb in det.robots:
        st_ = det.protocol.state[rb.id]
        assert rb.stopped and st_.chan.idle(), rb.id
        assert all(k in st_.final_t for k in st_.all_nbrs), rb.id
