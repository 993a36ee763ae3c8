"""The simulated network delivers a round's messages in the order they were sent (module
notes of pipeline.transport.simulated), with or without a delay, whatever their senders."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.transport.simulated import Network, NetworkOptions

STAR = [[0, 1], [0, 2], [0, 3]]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3), st.integers(0, 2)), min_size=1, max_size=30),
       st.integers(0, 3))
def test_a_round_delivers_in_send_order(sends, delay):
    net = Network(4, STAR, NetworkOptions(delay_rounds=delay))
    sent = {}  # (receiver, delivery round) -> payload tags in send order
    got = {}

    def end_round():
        net.end_round()
        for i in range(4):
            if net.inbox(i):
                got[(i, net.round)] = [int(m.payload["x"][0]) for m in net.inbox(i)]

    for x, (a, at) in enumerate(sorted(sends, key=lambda s: s[1])):
        while net.round < at:
            end_round()
        src, dst = (a, 0) if a else (0, 1 + x % 3)
        net.send(src, dst, "request", {"x": np.array([x], np.int32)})
        sent.setdefault((dst, net.round + 1 + delay), []).append(x)
    for _ in range(10):
        end_round()
    assert got == sent
