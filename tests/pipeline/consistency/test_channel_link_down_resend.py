"""The reliable channel on a switching link: a message kept while the link is down counts its
retransmission delay from the round it first goes out."""

import numpy as np

from pipeline.consistency.channel import Channel
from pipeline.consistency.protocols import ProtocolOptions
from pipeline.transport import Endpoint
from pipeline.transport.simulated import Network, NetworkOptions


class _LogEnd(Endpoint):
    def __init__(self, net, i, log):
        super().__init__(net, i)
        self.log = log

    def send(self, dst, kind, payload):
        self.log.append((self._transport.round, self.id, kind))
        super().send(dst, kind, payload)


def test_a_message_sent_while_the_link_is_down_goes_out_when_it_is_up_again():
    # the link is down in rounds 0 and 1, up from round 2 on
    net = Network(2, [[0, 1]], NetworkOptions(topology=lambda t: [] if t < 2 else [(0, 1)]))
    log = []
    chans = [Channel(_LogEnd(net, i, log), ProtocolOptions(reliable=True)) for i in range(2)]
    chans[0].send(1, "request", {"x": np.array([7], np.int32)}, 0)
    assert log == []
    delivered = []
    for _ in range(6):
        net.end_round()
        delivered += chans[1].receive(net.inbox(1), net.round)
        chans[0].receive(net.inbox(0), net.round)
        for c in chans:
            c.flush(net.round)
    # out in round 2, the first round the link is up; acknowledged in round 3, heard in round 4
    # (retransmit_after = 2 rounds after it went out): never sent twice, as on a link that was
    # up all along
    assert [(r, k) for r, src, k in log if src == 0] == [(2, "request")]
    assert [(r, k) for r, src, k in log if src == 1] == [(3, "ack")]
    assert len(delivered) == 1 and chans[0].idle() and chans[0].retransmissions == 0
