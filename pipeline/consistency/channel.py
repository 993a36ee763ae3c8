"""A robot's reliable links to its neighbours: sequence numbers, acknowledgements, retransmission.

Part of the fault-tolerant protocol of :mod:`pipeline.consistency.reliable` (see its docstring
for the rules and the wire format): every algorithm message to a neighbour gets a sequence
number, the receiver acknowledges it and delivers it once, an unacknowledged message is sent
again every round once ``retransmit_after`` rounds have passed, and a neighbour that stays
silent for ``loss_timeout`` rounds while expected is declared lost. The channel only sends
through the robot's own :class:`~pipeline.transport.Endpoint` (``send``, neighbour table).
"""

from __future__ import annotations

import numpy as np

from pipeline.transport import Endpoint, Message

__all__ = ["Channel"]

_I32 = np.int32


class _Pending:
    __slots__ = ("kind", "payload", "first", "last")

    def __init__(self, kind: str, payload: dict, first: int, last: int | None):
        self.kind, self.payload, self.first, self.last = kind, payload, first, last


class Channel:
    """A robot's reliable links to its neighbours (sequence numbers, acks, retransmission).

    Parameters
    ----------
    endpoint : Endpoint — the robot's side of the transport (``id``, ``send``, ``links_up``)
    options : ProtocolOptions — ``retransmit_after``, ``heartbeat_every``, ``loss_timeout``

    Attributes
    ----------
    lost : set of int — neighbours declared lost (ignored from then on)
    retransmissions, acks_sent, heartbeats_sent : int — counters of extra packets
    """

    def __init__(self, endpoint: Endpoint, options):
        self.owner = int(endpoint.id)
        self._send, self._links_up, self.options = endpoint.send, endpoint.links_up, options
        self._next_seq: dict[int, int] = {}
        self._unacked: dict[int, dict[int, _Pending]] = {}
        self._to_ack: dict[int, list[int]] = {}
        self._seen: dict[int, set[int]] = {}
        self._last_heard: dict[int, int] = {}
        self._last_sent: dict[int, int] = {}
        self._expect_since: dict[int, int] = {}
        self.lost: set[int] = set()
        self.retransmissions = 0
        self.acks_sent = 0
        self.heartbeats_sent = 0

    # --- receiving ------------------------------------------------------------------------
    def receive(self, inbox: list[Message], now: int) -> list[Message]:
        """Process acks, record what to acknowledge, return the new algorithm messages."""
        out = []
        for m in inbox:
            k = m.src
            if k in self.lost:
                continue
            self._last_heard[k] = now
            p = m.payload
            if "ack" in p:
                un = self._unacked.get(k)
                if un:
                    for s in p["ack"].tolist():
                        un.pop(int(s), None)
            seq = int(p["seq"][0]) if "seq" in p else 0
            if seq > 0:
                self._to_ack.setdefault(k, []).append(seq)
                seen = self._seen.setdefault(k, set())
                if seq not in seen:
                    seen.add(seq)
                    out.append(m)
        return out

    # --- sending --------------------------------------------------------------------------
    def _transmit(self, dst: int, kind: str, payload: dict, seq: int, now: int) -> None:
        p = dict(payload)
        p["seq"] = np.array([seq], dtype=_I32)
        acks = self._to_ack.pop(dst, None)
        if acks:
            p["ack"] = np.array(sorted(set(acks)), dtype=_I32)
        self._send(dst, kind, p)
        self._last_sent[dst] = now

    def send(self, dst: int, kind: str, payload: dict, now: int) -> None:
        """Send reliably (now if the link is up, else when it comes up)."""
        dst = int(dst)
        if dst in self.lost:
            return
        seq = self._next_seq.get(dst, 0) + 1
        self._next_seq[dst] = seq
        up = dst in self._links_up()
        self._unacked.setdefault(dst, {})[seq] = _Pending(kind, payload, now, now if up else None)
        self._expect_since.setdefault(dst, now)  # an ack is expected from now on
        if up:
            self._transmit(dst, kind, payload, seq, now)

    def flush(self, now: int, heartbeat_to=()) -> None:
        """End of a robot's round: retransmissions, pending acks, heartbeats."""
        up = self._links_up()
        rto = self.options.retransmit_after
        for k, un in self._unacked.items():
            if k not in up or k in self.lost:
                continue
            for seq, pm in un.items():
                if pm.last is None or (now - pm.first >= rto and pm.last < now):
                    if pm.last is not None:
                        self.retransmissions += 1
                    else:  # kept while the link was down: it goes out for the first time
                        pm.first = now
                    pm.last = now
                    self._transmit(k, pm.kind, pm.payload, seq, now)
        for k in [k for k in self._to_ack if k in up and k not in self.lost]:
            acks = self._to_ack.pop(k)
            self._send(k, "ack", {"seq": np.zeros(1, dtype=_I32),
                                  "ack": np.array(sorted(set(acks)), dtype=_I32)})
            self._last_sent[k] = now
            self.acks_sent += 1
        for k in heartbeat_to:
            if k in up and k not in self.lost and \
                    now - self._last_sent.get(k, -10**9) >= self.options.heartbeat_every:
                self._send(k, "heartbeat", {"seq": np.zeros(1, dtype=_I32)})
                self._last_sent[k] = now
                self.heartbeats_sent += 1

    # --- state ----------------------------------------------------------------------------
    def memory_bytes(self) -> int:
        """Bytes held for retransmission (payload arrays) and for duplicate detection."""
        held = sum(int(np.asarray(a).nbytes) for un in self._unacked.values()
                   for pm in un.values() for a in pm.payload.values())
        return held + 8 * sum(len(v) for v in self._seen.values())

    def idle(self) -> bool:
        """True when every message sent has been acknowledged (or its receiver is lost)."""
        return not any(un for k, un in self._unacked.items() if k not in self.lost)

    def check_lost(self, now: int, waiting_on=()) -> list[int]:
        """Neighbours silent for ``loss_timeout`` rounds while expected; marks them lost."""
        expected = {k for k, un in self._unacked.items() if un} | set(waiting_on)
        expected -= self.lost
        for k in list(self._expect_since):
            if k not in expected:
                del self._expect_since[k]
        newly = []
        for k in expected:
            since = self._expect_since.setdefault(k, now)
            quiet_from = max(since, self._last_heard.get(k, -10**9))
            if now - quiet_from >= self.options.loss_timeout:
                newly.append(k)
        for k in sorted(newly):
            self.lost.add(k)
            self._unacked.pop(k, None)
            self._to_ack.pop(k, None)
            self._expect_since.pop(k, None)
        return sorted(newly)
