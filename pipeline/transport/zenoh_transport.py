"""One robot's end of the team network over Zenoh (peer to peer, no broker).

Session (checked set-up, see the notes on Zenoh): ``mode: peer``, multicast scouting off and
gossip off, so a robot is connected exactly to the endpoints it is told: it listens on its own
endpoint and connects to its comm-graph neighbours' endpoints (and to the observer's, if the
team has one). No message can reach a robot that is not a neighbour.

Key expressions (``T`` = team name)
    ``fm/T/round/SRC/DST``  one packet per logical round from robot SRC to neighbour DST
    ``fm/T/hello/SRC/DST``  start handshake
    ``fm/T/alive/SRC/DST``  liveness beat
    ``fm/T/live/ID``        liveliness token of a robot
    ``fm/T/result/ID``      a robot's final result (for the observer)
    ``fm/T/ack/ID``         the observer's receipt of it
    ``fm/T/status/ID``      "started" / "failed: ..." (for the observer and the launcher)

Synchronous rounds over an asynchronous network (an α-synchronizer)
    In every logical round a robot sends *one packet to each neighbour*, holding the
    algorithm messages of that round (possibly none) and its round state, then waits for the
    packet of the same round from each neighbour. The inbox of the next round is then exactly
    what the in-process :class:`~pipeline.transport.simulated.Network` would deliver (same
    messages, ordered by sender id then sending order), so the shared algorithm code sees the
    same rounds as in the simulator.

Faults at this transport
    * ``drop_prob``: every *algorithm message* inside a packet is dropped with this probability
      (counted in ``dropped``) once :attr:`lossy` is set — by the robot when its consistency
      stage starts, as the simulator injects its faults into that stage only (the feature
      exchange before it relies on Zenoh's reliable TCP). The packet itself always goes,
      since it is the round's clock (the paper's synchronous round), not data. The robots' reliable protocol
      (:mod:`pipeline.consistency.reliable`) retransmits what is lost, as in the simulator.
    * Liveness: every robot holds a Zenoh liveliness token (``fm/T/live/ID``); when its
      process dies its session closes and the neighbours hear the token vanish within
      milliseconds: that neighbour is *silent* at once. For a machine that vanishes without
      closing anything, a background thread sends every neighbour a tiny ``alive`` beat every
      ``beat_s`` seconds, whatever the robot is computing. A neighbour from which neither a
      packet nor a beat arrived for ``round_timeout_s`` seconds is *silent* from then on: the robot stops waiting for it and its later packets are
      ignored. A neighbour that is merely slow (rendering, matching) keeps beating and is
      waited for. The robot is not told that it crashed: its protocol
      infers it from silence and cuts its links as ``robot-lost`` after ``T`` rounds.

Start handshake
    Each robot repeats ``hello`` to every neighbour (carrying whether it has heard that
    neighbour) until it has heard every neighbour and every neighbour has heard it, then sends
    one last ``hello``. A neighbour not heard within ``start_timeout_s`` is reported by id and
    endpoint (:class:`~pipeline.transport.RobotMissingError`).
"""

from __future__ import annotations

import json
import sys
import threading
import time

import numpy as np

from pipeline.errors import InputError
from pipeline.transport import Message, NotANeighbourError, RobotMissingError, RoundEndpoint
from pipeline.transport.wire import WireError, decode_packet, encode_packet

__all__ = ["ZenohTransport", "zenoh_config", "open_session", "key"]


def key(team: str, what: str, *ids) -> str:
    """Key expression ``fm/<team>/<what>/<id>/...``."""
    return "/".join(["fm", team, what, *(str(i) for i in ids)])


def zenoh_config(listen: list[str], connect: list[str]):
    """A peer-mode Zenoh config: no multicast scouting, no gossip, explicit endpoints."""
    import zenoh

    return zenoh.Config.from_json5(json.dumps({
        "mode": "peer",
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "listen": {"endpoints": list(listen)},
        "connect": {"endpoints": list(connect)},
    }))


def open_session(listen: list[str], connect: list[str], who: str):
    """Open a Zenoh session; a listen endpoint that cannot be bound is one InputError line."""
    import zenoh

    try:
        return zenoh.open(zenoh_config(listen, connect))
    except zenoh.ZError as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else "zenoh error"
        ep = listen[0] if listen else "?"
        if "in use" in msg.lower() or "bind" in msg.lower() or "listen" in msg.lower():
            raise InputError(f"{who}: cannot listen on {ep} (port in use?): {msg}") from None
        raise InputError(f"{who}: cannot open a Zenoh session on {ep}: {msg}") from None


class ZenohTransport(RoundEndpoint):
    """Robot ``robot_id`` of ``team`` talking to its neighbours over Zenoh.

    Parameters
    ----------
    team : pipeline.team.teamfile.Team
    robot_id : int
    drop_prob : float in [0, 1) — loss injected on outgoing algorithm messages
    seed : int — seed of the drops (combined with the robot id)
    round_timeout_s : float — silence (no packet, no beat) after which a neighbour is lost
    beat_s : float — period of the liveness beats
    log : callable(str) or None — progress lines (default: stderr)
    """

    def __init__(self, team, robot_id: int, *, drop_prob: float = 0.0, seed: int = 0,
                 round_timeout_s: float = 5.0, beat_s: float = 0.2, log=None) -> None:
        self.team = team
        self.robot_id = int(robot_id)
        self.neighbours = frozenset(team.neighbours(self.robot_id))
        self.round = 0
        self.drop_prob = float(drop_prob)
        self.lossy = False  # set by the robot when its consistency stage starts
        self._rng = np.random.default_rng([int(seed), 7, self.robot_id])
        self.round_timeout_s = float(round_timeout_s)
        self._log = log or (lambda s: print(s, file=sys.stderr, flush=True))
        self.silent: set[int] = set()
        self._out: dict[int, list[tuple[str, dict]]] = {k: [] for k in self.neighbours}
        self._packets: dict[tuple[int, int], tuple[dict, list]] = {}
        self._hello: dict[int, bool] = {}
        self._cv = threading.Condition()
        self._heard: dict[int, float] = {}
        self.beat_s = float(beat_s)
        self._stop = threading.Event()
        self.messages = self.bytes = self.dropped = 0
        self.wire_bytes = self.wire_packets = 0
        self.messages_by_kind: dict[str, int] = {}
        self.bytes_by_kind: dict[str, int] = {}
        self.wait_s = 0.0
        connect = [team.endpoint(k) for k in sorted(self.neighbours)]
        if team.observer:
            connect.append(team.observer)
        self.session = open_session([team.endpoint(self.robot_id)], connect,
                                    f"robot {self.robot_id}")
        name = team.name
        self._subs = []
        for k in sorted(self.neighbours):
            self._subs.append(self.session.declare_subscriber(
                key(name, "round", k, self.robot_id), self._on_packet))
            self._subs.append(self.session.declare_subscriber(
                key(name, "hello", k, self.robot_id), self._on_hello))
            self._subs.append(self.session.declare_subscriber(
                key(name, "alive", k, self.robot_id), self._on_beat))
        import zenoh

        # round packets must never be dropped by Zenoh itself (its default under congestion
        # is to drop): the round clock relies on every packet arriving
        self._pubs = {k: self.session.declare_publisher(
            key(name, "round", self.robot_id, k),
            congestion_control=zenoh.CongestionControl.BLOCK)
            for k in sorted(self.neighbours)}
        self._beat_pubs = {k: self.session.declare_publisher(
            key(name, "alive", self.robot_id, k)) for k in sorted(self.neighbours)}
        self._beater = threading.Thread(target=self._beat, daemon=True)
        self._beater.start()
        # a robot's liveliness token vanishes as soon as its session does (process killed:
        # the kernel closes its sockets), which its neighbours hear within milliseconds
        self._left: set[int] = set()
        self._token = self.session.liveliness().declare_token(key(name, "live", self.robot_id))
        for k in sorted(self.neighbours):
            self._subs.append(self.session.liveliness().declare_subscriber(
                key(name, "live", k), self._on_liveliness))

    def _on_liveliness(self, sample) -> None:
        import zenoh

        if sample.kind != zenoh.SampleKind.DELETE:
            return
        k = int(str(sample.key_expr).rsplit("/", 1)[-1])
        with self._cv:
            self._left.add(k)
            self._cv.notify_all()

    def _beat(self) -> None:
        while not self._stop.wait(self.beat_s):
            for pub in self._beat_pubs.values():
                try:
                    pub.put(b"1")
                except Exception:  # noqa: BLE001 - the session is closing
                    return

    def _on_beat(self, sample) -> None:
        k = int(str(sample.key_expr).split("/")[-2])
        with self._cv:
            self._heard[k] = time.monotonic()

    # --- callbacks (Zenoh threads) --------------------------------------------------------
    def _on_packet(self, sample) -> None:
        try:
            header, msgs = decode_packet(sample.payload.to_bytes())
        except WireError as exc:
            self._log(f"robot {self.robot_id}: dropped a malformed packet on "
                      f"{sample.key_expr}: {exc}")
            return
        with self._cv:
            self._packets[(int(header["src"]), int(header["round"]))] = (header, msgs)
            self._heard[int(header["src"])] = time.monotonic()
            self._cv.notify_all()

    def _on_hello(self, sample) -> None:
        try:
            doc = json.loads(sample.payload.to_bytes())
            src, heard_me = int(doc["src"]), bool(doc["heard"])
        except (ValueError, KeyError, TypeError):
            return
        with self._cv:
            self._hello[src] = self._hello.get(src, False) or heard_me
            self._cv.notify_all()

    # --- start ----------------------------------------------------------------------------
    def handshake(self, timeout_s: float = 60.0, period_s: float = 0.05) -> float:
        """Wait until every neighbour is heard and has heard this robot; return seconds taken.

        Raises
        ------
        RobotMissingError
            Some neighbour was not heard within ``timeout_s``; the message names it.
        """
        t0 = time.monotonic()
        name = self.team.name

        def say():
            for k in sorted(self.neighbours):
                with self._cv:
                    heard = k in self._hello
                self.session.put(key(name, "hello", self.robot_id, k),
                                 json.dumps({"src": self.robot_id, "heard": heard}))

        while True:
            say()
            with self._cv:
                ok = all(self._hello.get(k, False) for k in self.neighbours)
                if not ok:
                    self._cv.wait(period_s)
                    ok = all(self._hello.get(k, False) for k in self.neighbours)
                missing = sorted(k for k in self.neighbours if k not in self._hello)
            if ok:
                say()  # the last one tells late neighbours that they were heard
                return time.monotonic() - t0
            if time.monotonic() - t0 > timeout_s:
                if not missing:
                    missing = sorted(k for k in self.neighbours if not self._hello.get(k))
                k = missing[0]
                raise RobotMissingError(
                    f"robot {self.robot_id}: neighbour robot {k} ({self.team.endpoint(k)}) did "
                    f"not answer within {timeout_s:g} s; it never started or cannot be reached")

    # --- rounds ---------------------------------------------------------------------------
    def send(self, dst: int, kind: str, payload: dict) -> None:
        dst = int(dst)
        if dst not in self.neighbours:
            raise NotANeighbourError(f"robot {self.robot_id} tried to send a {kind!r} message "
                                     f"to robot {dst}, which is not its neighbour")
        msg = Message(self.robot_id, dst, kind, payload, self.round)
        size = msg.nbytes
        self.messages += 1
        self.bytes += size
        self.messages_by_kind[kind] = self.messages_by_kind.get(kind, 0) + 1
        self.bytes_by_kind[kind] = self.bytes_by_kind.get(kind, 0) + size
        if self.lossy and self.drop_prob > 0.0 and self._rng.random() < self.drop_prob:
            self.dropped += 1
            return
        self._out[dst].append((kind, payload))

    def end_round(self, state: dict | None = None) -> tuple[list[Message], dict[int, dict]]:
        r = self.round
        for k in sorted(self.neighbours):
            msgs, self._out[k] = self._out[k], []
            if k in self.silent:
                continue
            data = encode_packet({"src": self.robot_id, "dst": k, "round": r,
                                  "state": state or {}}, msgs)
            self.wire_bytes += len(data)
            self.wire_packets += 1
            self._pubs[k].put(data)
        t0 = time.monotonic()
        with self._cv:
            for k in self.neighbours:
                self._heard.setdefault(k, t0)
            while True:
                waiting = [k for k in self.neighbours
                           if k not in self.silent and (k, r) not in self._packets]
                if not waiting:
                    break
                now = time.monotonic()
                gone = [k for k in waiting
                        if k in self._left or now - self._heard[k] > self.round_timeout_s]
                for k in gone:
                    self.silent.add(k)
                    why = ("its Zenoh session closed" if k in self._left else
                           f"nothing from it for {self.round_timeout_s:g} s")
                    self._log(f"robot {self.robot_id}: robot {k} is silent from round {r} on "
                              f"({why})")
                if len(gone) == len(waiting):
                    break
                self._cv.wait(min(self.beat_s, self.round_timeout_s))
            got = {k: self._packets.pop((k, r)) for k in sorted(self.neighbours)
                   if k not in self.silent and (k, r) in self._packets}
            for kk in [kk for kk in self._packets if kk[1] <= r]:
                del self._packets[kk]  # late packets of silent robots
        self.wait_s += time.monotonic() - t0
        self.round = r + 1
        inbox = [Message(k, self.robot_id, kind, payload, r)
                 for k, (_, msgs) in got.items() for kind, payload in msgs]
        self._last_inbox = inbox
        return inbox, {k: h.get("state", {}) for k, (h, _) in got.items()}

    def counters(self) -> dict:
        return dict(messages=self.messages, bytes=self.bytes, dropped=self.dropped,
                    round=self.round, messages_by_kind=dict(self.messages_by_kind),
                    bytes_by_kind=dict(self.bytes_by_kind), wire_bytes=self.wire_bytes,
                    wire_packets=self.wire_packets, wait_s=round(self.wait_s, 4),
                    silent=sorted(self.silent))

    # --- results --------------------------------------------------------------------------
    def status(self, text: str) -> None:
        """Publish a one-line status for the observer (``started``, ``failed: ...``)."""
        self.session.put(key(self.team.name, "status", self.robot_id), text)

    def publish_result(self, data: bytes, wait_s: float = 10.0, period_s: float = 0.25) -> bool:
        """Publish the final result until the observer acknowledges it (or ``wait_s``).

        Returns True when acknowledged (always False without an observer in the team).
        """
        import zenoh

        got = threading.Event()
        name = self.team.name
        sub = self.session.declare_subscriber(key(name, "ack", self.robot_id),
                                              lambda s: got.set())
        try:
            t0 = time.monotonic()
            while True:
                self.session.put(key(name, "result", self.robot_id), data,
                                 congestion_control=zenoh.CongestionControl.BLOCK)
                if not self.team.observer or got.wait(period_s):
                    return got.is_set()
                if time.monotonic() - t0 > wait_s:
                    return False
        finally:
            sub.undeclare()

    def close(self) -> None:
        self._stop.set()
        try:
            self.session.close()
        except Exception:  # noqa: BLE001 - closing a session that is already gone
            pass
