"""The reliable channel under any loss pattern it tolerates: every message delivered exactly
once, nothing left unacknowledged, nobody suspected; a neighbour declared lost is ignored."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.consistency.channel import Channel
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.transport import Endpoint
from pipeline.transport.simulated import Network

T = 40
OPTIONS = ProtocolOptions(reliable=True, loss_timeout=T)


class _LossyEnd(Endpoint):
    """A robot's endpoint that loses the sendings the pattern marks (then none)."""

    def __init__(self, net, i, pattern, log):
        super().__init__(net, i)
        self.pattern, self.log = list(pattern), log

    def send(self, dst, kind, payload):
        self.log.append((self._transport.round, self.id, kind, int(payload["seq"][0])))
        if self.pattern and self.pattern.pop(0):
            return
        super().send(dst, kind, payload)


def _pair(patterns, options=OPTIONS):
    net = Network(2, [[0, 1]])
    log = []
    ends = [_LossyEnd(net, i, patterns[i], log) for i in range(2)]
    return net, [Channel(e, options) for e in ends], log, ends


def _step(net, chans, delivered):
    net.end_round()
    now = net.round
    for i, c in enumerate(chans):
        for m in c.receive(net.inbox(i), now):
            delivered[i].append((m.src, int(m.payload["x"][0])))
    lost = [c.check_lost(now) for c in chans]
    for c in chans:
        c.flush(now)
    return lost


# a loss pattern per robot: which of its first 16 sendings are lost (any of them; then none).
# The timeout tolerates it: a sending is retried every round, so with at most 16 + 16 losses a
# neighbour is heard within 2 * 16 + 2 rounds < T
_PATTERN = st.lists(st.booleans(), max_size=16)


@settings(max_examples=150, deadline=None)
@given(_PATTERN, _PATTERN, st.lists(st.tuples(st.integers(0, 1), st.integers(0, 6)),
                                    min_size=1, max_size=12))
def test_every_message_is_delivered_once_under_any_tolerated_loss(p0, p1, sends):
    net, chans, log, _ = _pair([p0, p1])
    delivered = [[], []]
    expected = [[], []]
    for x, (src, at) in enumerate(sorted(sends, key=lambda s: s[1])):
        while net.round < at:
            assert _step(net, chans, delivered) == [[], []]
        chans[src].send(1 - src, "request", {"x": np.array([x], np.int32)}, net.round)
        expected[1 - src].append((src, x))
    for _ in range(200):
        if all(c.idle() for c in chans):
            break
        assert _step(net, chans, delivered) == [[], []]  # a live neighbour is never suspected
    assert all(c.idle() for c in chans)
    assert [sorted(d) for d in delivered] == [sorted(e) for e in expected]
    # and then quiet: nothing is sent once everything is acknowledged
    quiet = len(log)
    for _ in range(5):
        _step(net, chans, delivered)
    assert len(log) == quiet
    # the counters say what was sent: every sending of a sequence number after its first is a
    # retransmission, every acknowledgement alone an ack
    for i, c in enumerate(chans):
        firsts = {(k, s) for _, src, k, s in log if src == i and s > 0}
        sequenced = sum(1 for _, src, k, s in log if src == i and s > 0)
        assert c.retransmissions == sequenced - len(firsts)
        assert c.acks_sent == sum(1 for _, src, k, _ in log if src == i and k == "ack")


def test_a_neighbour_declared_lost_is_ignored_from_then_on():
    net, chans, _, ends = _pair([[True] * 100, []])  # robot 0 is never heard by robot 1
    delivered = [[], []]
    chans[1].send(0, "request", {"x": np.array([1], np.int32)}, 0)
    lost_at = None
    for _ in range(T + 2):
        lost = _step(net, chans, delivered)
        if lost[1]:
            lost_at = net.round
    assert lost_at == T and chans[1].lost == {0}
    # what it held for robot 0 is dropped: nothing left to retransmit, nothing held
    assert chans[1].idle() and chans[1].memory_bytes() == 0
    # robot 0 heard robot 1's request; a message it sends now is not delivered to robot 1,
    # and robot 1 neither acknowledges it nor counts robot 0 as heard
    ends[0].pattern = []
    chans[0].send(1, "request", {"x": np.array([2], np.int32)}, net.round)
    for _ in range(4):
        _step(net, chans, delivered)
    assert delivered[1] == [] and delivered[0] == [(1, 1)]
    assert not chans[0].idle()


def test_an_unacknowledged_message_is_sent_again_every_round_after_retransmit_after():
    # robot 0's first three sendings are lost: sent at round 0, again at round 2 (two rounds
    # after the first), then every round until the acknowledgement is in (sent by robot 1 in
    # round 5, heard in round 6)
    net, chans, log, _ = _pair([[True, True, True], []])
    chans[0].send(1, "request", {"x": np.array([7], np.int32)}, 0)
    delivered = [[], []]
    for _ in range(10):
        _step(net, chans, delivered)
    assert [r for r, src, k, _ in log if src == 0 and k == "request"] == [0, 2, 3, 4, 5]
    assert [r for r, src, k, _ in log if src == 1 and k == "ack"] == [5, 6]
    assert delivered[1] == [(0, 7)] and chans[0].idle() and chans[0].retransmissions == 4



def test_new_messages_to_a_silent_neighbour_do_not_put_off_its_timeout():
    net, chans, _, _ = _pair([[], [True] * 1000])  # robot 0 never hears robot 1
    delivered = [[], []]
    lost_at = None
    for x in range(T + 2):
        chans[0].send(1, "request", {"x": np.array([x], np.int32)}, net.round)
        lost = _step(net, chans, delivered)
        if lost[0] and lost_at is None:
            lost_at = net.round
    assert lost_at == T and chans[0].lost == {1}


def test_a_neighbour_heard_every_round_is_never_lost_however_long_it_is_waited_for():
    net, chans, _, _ = _pair([[], []])
    heard = None
    for _ in range(3 * T):
        net.end_round()
        now = net.round
        heard = now if net.inbox(0) else heard
        for i, c in enumerate(chans):
            c.receive(net.inbox(i), now)
        # robot 0 waits for something from robot 1 all along; robot 1 only sends heartbeats
        assert chans[0].check_lost(now, waiting_on=[1]) == []
        chans[0].flush(now)
        chans[1].flush(now, heartbeat_to=[0])
    # one heartbeat every heartbeat_every = 2 rounds (rounds 1, 3, 5, ...), nothing else
    assert chans[0].lost == set() and chans[1].heartbeats_sent == 3 * T // 2
    # silent from now on (robot 1 no longer steps): lost T rounds after it was last heard
    for _ in range(2 * T):
        if chans[0].lost:
            break
        net.end_round()
        heard = net.round if net.inbox(0) else heard
        chans[0].receive(net.inbox(0), net.round)
        chans[0].check_lost(net.round, waiting_on=[1])
    assert chans[0].lost == {1} and net.round - heard == T
