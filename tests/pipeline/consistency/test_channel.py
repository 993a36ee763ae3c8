"""The reliable channel: acknowledgements, retransmission, duplicate delivery, timeouts."""

import itertools

import numpy as np

from pipeline.consistency.channel import Channel
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.transport import Endpoint
from pipeline.transport.simulated import Network

RELIABLE = ProtocolOptions(reliable=True)


class _SpyEndpoint(Endpoint):
    """A robot's endpoint that logs what it sends and loses what the wire's ``drop`` says."""

    def __init__(self, wire, i):
        super().__init__(wire.net, i)
        self.wire = wire

    def send(self, dst, kind, payload):
        self.wire.sent.append((self.wire.net.round, self.id, kind))
        if not self.wire.drop(kind):
            super().send(dst, kind, payload)


class _Wire:
    """Two channels over a network; ``drop`` decides per message whether it is lost."""

    def __init__(self, options=RELIABLE):
        self.net = Network(2, [[0, 1]])
        self.sent = []
        self.drop = lambda msg_kind: False
        self.ch = [Channel(_SpyEndpoint(self, i), options) for i in range(2)]

    def step(self):
        self.net.end_round()
        now = self.net.round
        got = [self.ch[i].receive(self.net.inbox(i), now) for i in range(2)]
        for c in self.ch:
            c.flush(now)
        return got


def test_channel_lossless_round_trip_sends_nothing_twice():
    w = _Wire()
    w.ch[0].send(1, "request", {"q": np.array([3], np.int32)}, 0)
    got = w.step()
    assert [m.kind for m in got[1]] == ["request"]
    assert not w.ch[0].idle()
    w.step()  # the ack arrives exactly retransmit_after = 2 rounds after sending
    assert w.ch[0].idle() and w.ch[0].retransmissions == 0
    assert [k for _, _, k in w.sent] == ["request", "ack"]


def test_channel_retransmits_until_acked_and_delivers_once():
    w = _Wire()
    lose = itertools.chain([True], itertools.repeat(False))  # only the first sending is lost
    w.drop = lambda kind: next(lose) if kind == "request" else False
    w.ch[0].send(1, "request", {"q": np.array([3], np.int32)}, 0)
    delivered = []
    for _ in range(6):
        delivered += w.step()[1]
    assert [m.kind for m in delivered] == ["request"] and w.ch[0].idle()
    assert w.ch[0].retransmissions >= 1
    # lost acks: the request arrives twice, is delivered once
    w = _Wire()
    acks = itertools.chain([True], itertools.repeat(False))
    w.drop = lambda kind: next(acks) if kind == "ack" else False
    w.ch[0].send(1, "request", {"q": np.array([3], np.int32)}, 0)
    delivered = []
    for _ in range(6):
        delivered += w.step()[1]
    assert len(delivered) == 1 and w.ch[0].idle()
    assert sum(1 for _, src, k in w.sent if src == 0 and k == "request") >= 2


def test_channel_declares_a_silent_neighbour_lost_after_T_rounds():
    w = _Wire(ProtocolOptions(reliable=True, loss_timeout=5))
    w.drop = lambda kind: True  # robot 1 never hears anything, robot 0 never hears back
    w.ch[0].send(1, "request", {"q": np.array([3], np.int32)}, 0)
    lost_at = None
    for _ in range(10):
        w.step()
        if w.ch[0].check_lost(w.net.round) and lost_at is None:
            lost_at = w.net.round
    assert lost_at == 5 and w.ch[0].lost == {1} and w.ch[0].idle()
    # nothing expected from a neighbour: silence is not suspicious
    assert w.ch[1].check_lost(w.net.round) == []
