"""The simulated network: neighbours only, next-round delivery, counting, fault switches."""

import numpy as np
import pytest

from pipeline.consistency.network import HEADER_BYTES, Network, NetworkOptions, NotANeighbourError

EDGES = [[0, 1], [1, 2]]


def payload(k):
    return {"rows": np.arange(k, dtype=np.int32)}


def test_send_only_to_neighbours():
    net = Network(3, EDGES)
    with pytest.raises(NotANeighbourError, match="robot 0 .* robot 2"):
        net.send(0, 2, "blocks", payload(1))


def test_delivery_next_round_and_counters():
    net = Network(3, EDGES)
    net.send(0, 1, "blocks", payload(3))
    net.send(2, 1, "request", payload(1))
    assert net.inbox(1) == [] and net.pending
    net.end_round()
    got = sorted((m.src, m.kind) for m in net.inbox(1))
    assert got == [(0, "blocks"), (2, "request")]
    assert not net.pending
    assert net.messages == 2
    assert net.bytes == 2 * HEADER_BYTES + 4 * 3 + 4 * 1
    assert net.counters()["bytes_by_kind"] == {"blocks": HEADER_BYTES + 12, "request": HEADER_BYTES + 4}
    net.end_round()
    assert net.inbox(1) == []


def test_fault_switches():
    net = Network(3, EDGES, NetworkOptions(delay_rounds=2))
    net.send(0, 1, "blocks", payload(1))
    net.end_round()
    net.end_round()
    assert net.inbox(1) == []
    net.end_round()
    assert len(net.inbox(1)) == 1

    net = Network(3, EDGES, NetworkOptions(drop_probability=1.0))
    net.send(0, 1, "blocks", payload(1))
    net.end_round()
    assert net.inbox(1) == [] and net.dropped == 1 and net.messages == 1

    net = Network(3, EDGES, NetworkOptions(crashed=frozenset({1})))
    assert net.neighbours(0) == frozenset()
    net.send(2, 1, "blocks", payload(1))
    net.end_round()
    assert net.inbox(1) == []

    net = Network(3, EDGES, NetworkOptions(topology=lambda t: EDGES if t == 0 else [[0, 2]]))
    net.send(0, 1, "blocks", payload(1))
    net.end_round()
    with pytest.raises(NotANeighbourError):
        net.send(0, 1, "blocks", payload(1))
    net.send(0, 2, "blocks", payload(1))
