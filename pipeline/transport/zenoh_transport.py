"""One robot's end of the team network over Zenoh (peer to peer, no broker).

Session (checked set-up, see the notes on Zenoh): ``mode: peer``, multicast scouting off and
gossip off, so a robot is connected exactly to the endpoints it is told: it listens on its own
endpoint and connects to the endpoints of its comm-graph neighbours of *lower* id (and to the
observer's, if the team has one); its neighbours of higher id connect to it. No message can
reach a robot that is not a neighbour. Each link is opened from one end: two peers that open
a session to each other at the same moment can both lose it (eclipse-zenoh/zenoh#169), which
left two robots of a test unconnected for 20 s now and then. A robot whose lower neighbour
is not listening yet tries again after 0.1 s, doubling up to 1 s (``connect.retry``; Zenoh's
default, 1 s up to 4 s, made a late neighbour wait about 2 s).

Key expressions (``T`` = team name)
    ``fm/T/round/SRC/DST``  one packet per logical round from robot SRC to neighbour DST
    ``fm/T/hello/SRC/DST``  start handshake
    ``fm/T/alive/SRC/DST``  liveness beat
    ``fm/T/gone/SRC/DST``   SRC wrote DST off (see "Writing a neighbour off")
    ``fm/T/again/SRC/DST``  SRC asks DST to send its packet of a round again (payload: the
                            round; see "A round packet lost")
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
      milliseconds. For a machine that vanishes without closing anything, a background thread
      sends every neighbour still counted on a tiny ``alive`` beat every ``beat_s`` seconds
      (:func:`beat_period`: a thirtieth of the round timeout, from 0.2 to 5 s), whatever the
      robot is computing. A neighbour
      that is merely slow (rendering, matching) keeps beating and is waited for.

A round packet lost
    Round packets go with Zenoh's blocking congestion control, so Zenoh never drops one on a
    full queue; yet a packet can still be lost with the link it was queued on (a link closed
    and reopened under load: observed with two 18-robot teams started at once on two cores,
    where a team stalled with every robot waiting in one round for a neighbour that kept
    beating). A robot that has waited :data:`ASK_AFTER_S` for a neighbour's packet of the
    current round while hearing its beats asks it for that packet (``again``, at most once
    per :data:`ASK_AFTER_S`); a robot keeps its packets of its last two rounds and sends the
    asked one again (a neighbour may still wait for the round before this robot's: it moved
    on when it got the neighbour's packet). A packet that arrives twice is kept once (it is
    stored by sender and round). A neighbour that has not sent the round yet ignores the
    request. Counted in ``resent`` and ``asked``.

Writing a neighbour off (no hang, ever)
    A robot stops waiting for neighbour ``k`` — *writes it off* — for one of five reasons,
    kept in :attr:`ZenohTransport.written_off`:

    ``closed``   its Zenoh session closed (liveliness token gone): its process ended (in a
                 round, :data:`CLOSED_GRACE_S` after that, for its last packet to arrive);
    ``silent``   nothing from it (no packet, no beat) for ``round_timeout_s`` seconds: a host
                 frozen, or the link between them down (the robot cannot tell which);
    ``told``     ``k`` wrote *this* robot off and said so (``fm/T/gone/K/ID``);
    ``limit``    one round waited ``round_limit_s`` seconds for ``k``, which kept beating
                 without sending the round's packet;
    ``start``    ``k`` did not answer the start handshake within ``start_timeout_s`` (while
                 another neighbour did; with none heard the robot stops, naming one).

    Writing off is final and made symmetric: the robot stops sending ``k`` round packets *and
    beats*, publishes ``gone`` to it at once and again whenever it hears from it later (at most
    once per beat period), so ``k`` writes this robot off too (``told``) — or, if the notice
    cannot reach it, by silence after its own ``round_timeout_s``. The neighbour's late
    packets are ignored. The robot's protocol then sees nothing more from ``k`` and cuts its
    links as ``robot-lost`` after ``T`` rounds (:mod:`pipeline.consistency.reliable`), on both
    ends. (Before, a robot written off by one neighbour kept receiving that neighbour's beats,
    so it waited for that neighbour's packets for ever, and its other neighbours for it: a
    cycle of waits around a ring.)

    Bounds, stated for :meth:`ZenohTransport.end_round`: the packets are queued to the
    neighbour's sender thread (see "Threads"; a put into a slow link's full queue blocks that
    sender only, at most ``block_s`` seconds per packet before Zenoh closes that link, which
    reads as ``closed``), and the wait ends within ``round_limit_s`` plus one beat period
    whatever the neighbours do. A round therefore never waits for ever;
    a robot that writes off every neighbour runs its remaining rounds alone, without waiting.
    :meth:`ZenohTransport.outcome` names how the robot ended: ``done`` (no neighbour written
    off), ``cut`` (only neighbours whose process ended), ``partitioned`` (a neighbour went
    silent, wrote it off or never answered: frozen, a link down, not started), ``gave-up`` (a
    round hit ``round_limit_s``).

Rejoin (the rule, and why nothing is lost)
    Rule: a neighbour is waited for until it is written off (above), never merely because it
    is late. Claim: if no neighbour of any robot is written off — every host that froze
    resumed, every link that went down came back, and every robot that started late started,
    within ``round_timeout_s`` of its last word (``start_timeout_s`` at the start) — then every
    robot receives exactly the inboxes of an undisturbed run, so the team's decisions (every
    link's status, reason and round) are those of the run without the fault: the frozen or cut
    off robot is taken back with its links decided with the rest, nothing is lost.
    Proof: (1) nothing in flight is lost. The session keeps a link through a silence of up
    to ``lease_s`` = ``2·round_timeout_s + 10`` s (Zenoh's lease) and a blocked put up to
    ``block_s`` = ``round_timeout_s + 5`` s, both longer than any silence that is not written
    off, so the Zenoh session and its TCP connection stay open and TCP delivers every byte,
    in order, once the link or the host is back. (2) The α-synchronizer's round ``r`` ends
    only when the round-``r`` packet of every neighbour not written off has arrived, and by
    (1) it does arrive; so the inbox of round ``r + 1`` is the same set of messages, in the
    same order (by sender then sending order), whatever the delays. (3) The robot code is
    deterministic given its inboxes (the injected drops are seeded per robot and per
    message, not per time), so by induction on rounds every robot makes the same decisions
    as without the fault. Only time is spent: the rounds of the whole team stall while one
    robot is silent. When a robot *is* written off, its links are cut as ``robot-lost`` by
    both ends, so the team still ends conflict-free (the survivors repeat detection after a
    loss, :mod:`pipeline.consistency.termination`), and the run reports the links it lost.

Threads
    A robot's threads do not grow with its neighbours beyond :data:`SENDER_THREADS`: its round
    packets go through at most that many sender threads, neighbour ``k`` always through the
    same one (the ``n``-th neighbour by id through sender ``n mod SENDER_THREADS``), so each
    neighbour's packets are put in the order they were queued. A robot with at most
    :data:`SENDER_THREADS` neighbours has one sender per neighbour, and a put into a slow
    link's full queue holds up that link only; with more, it also holds up the neighbours that
    share its sender, by at most ``block_s`` per packet (they keep hearing this robot's beats,
    so they wait, and ask for the packet again, see "A round packet lost"). Every Python
    callback of a Zenoh subscriber runs on a thread of its own, so the robot declares one
    subscriber per key kind for all its neighbours (``fm/T/round/*/ID``, ...; what comes from
    a robot that is not a neighbour is ignored), not one per neighbour and kind: with those
    and a sender per neighbour, a robot ran seven threads per neighbour, 700 on a complete
    graph of 101 images and 70,000 for the team on one machine. One more thread sends the
    beats.

Start handshake
    Each robot repeats ``hello`` to every neighbour (carrying whether it has heard that
    neighbour) until it has heard every neighbour and every neighbour has heard it, then sends
    one last ``hello``. A neighbour that starts late within ``start_timeout_s`` joins; one not
    heard by then is written off (``start``) and named in the log, and the robot runs on with
    the others; if no neighbour at all was heard, the robot stops and names one
    (:class:`~pipeline.transport.RobotMissingError`). That last ``hello`` may be lost (the
    robot killed before Zenoh sent it; a test caught a neighbour then waiting the whole
    timeout for a robot that had long started): a robot that has finished its handshake
    answers every ``hello`` it still gets with one of its own, so a neighbour still waiting
    is told it was heard; and a neighbour heard once whose session then closes (liveliness
    token gone) is written off at once (``closed``), not after the timeout. A neighbour that
    ends before it was heard leaves no token to vanish; in a launcher's team (option
    ``closed_at_start``: no robot is started again there) the launcher, which saw its
    process end, declares a token ``ended/<id>`` for it, which the robot finds (a liveliness
    query every :data:`ENDED_ASK_S` while a neighbour is unheard) and writes it off then too
    (``closed``).

    A neighbour started again: every hello carries a mark drawn by the robot's process when
    it starts (:attr:`ZenohTransport.incarnation`). A hello of another mark than the first
    heard from that neighbour comes from a new process of it (killed, then started again with
    the same id), whose first process took part and ended without finishing: the first is
    written off (``closed``, as its session closed) and the new one is told ``gone``, so it
    ends alone (``told``) instead of joining rounds it never ran (it used to finish the
    handshake, be sent the earlier process's round packets when it asked for them, and have
    its packets taken for the rounds its first process left).

    Paced hellos: a robot tells a neighbour at once when it first hears it (its ``heard`` bit
    changes); otherwise it repeats its hello to that neighbour after 0.05 s, then after twice
    as long each time, up to :data:`HELLO_EVERY_MAX_S` (a first hello can be lost while the
    link is still being opened). It used to send a hello to every neighbour on every turn of
    its loop, and each hello it received woke the loop: ``d`` neighbours sent it about ``d``
    hellos per turn, each answered by ``d`` puts, so the handshake cost grew as ``d²`` per
    robot. A team of 101 robots on the complete graph spent about 590 s in it at load
    average 400 on this 2-core machine, and wrote off 411 neighbours it never heard.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import re
import sys
import threading
import time

import numpy as np

from pipeline.errors import InputError
from pipeline.transport import Message, NotANeighbourError, RobotMissingError, RoundEndpoint
from pipeline.transport.wire import WireError, decode_packet, encode_packet

__all__ = ["ZenohTransport", "zenoh_config", "open_session", "key", "ASK_AFTER_S",
           "SENDER_THREADS"]


def key(team: str, what: str, *ids) -> str:
    """Key expression ``fm/<team>/<what>/<id>/...``."""
    return "/".join(["fm", team, what, *(str(i) for i in ids)])


def link_timeouts(round_timeout_s: float) -> tuple[float, float]:
    """``(lease_s, block_s)`` of a robot's Zenoh session: longer than any silence the robot
    does not write off, so a session outlives every fault it is meant to survive (module
    docstring, "Rejoin", step 1)."""
    return 2.0 * float(round_timeout_s) + 10.0, float(round_timeout_s) + 5.0


#: seconds a robot waits for a neighbour's round packet, while hearing its beats, before it
#: asks for it again (and again every so many seconds): a packet lost with its link
ASK_AFTER_S = 2.0

#: seconds a robot still waits for a neighbour's round packet after the neighbour's session
#: closed (liveliness token gone), before it writes the neighbour off (``closed``): a robot
#: that sent its last packet and ended at once is heard to end on one callback thread while
#: its packet, already received, is still being decoded on another (a few MB of features
#: under load), and was written off with the packet in hand (its neighbour then stopped: "the
#: features of frame F never came from robot K")
CLOSED_GRACE_S = 2.0

#: seconds between two queries of a robot in the start handshake, while a neighbour is
#: unheard, for its launcher's ``ended`` tokens (``closed_unheard``), and the longest one waits
ENDED_ASK_S = 0.5

#: the most sender threads a robot runs (module docstring, "Threads"): one per neighbour up
#: to this many, so a robot of the project's sparse graphs (line, ring: 2 neighbours, ring2: 4,
#: formations a-d: 5, seq:3: 6) keeps a thread per link; a robot with more neighbours (a
#: complete graph of 101 images: 100) shares them, where one per neighbour made 10,000
#: threads on one machine and a robot could not start its own
SENDER_THREADS = 8

def beat_period(round_timeout_s: float) -> float:
    """Seconds between two liveness beats to a neighbour: a thirtieth of the silence that
    writes it off, from 0.2 s to 5 s. A live neighbour then beats about 30 times within its
    round timeout. The beats were sent every 0.2 s whatever the timeout: with 100 neighbours
    a robot put 500 beats a second and took as many callbacks, 50,000 a second for a team of
    101 robots on the complete graph of one 2-core machine."""
    return min(max(0.2, float(round_timeout_s) / 30.0), 5.0)


#: the longest a robot waits before it repeats its hello to a neighbour in the start handshake
#: (module docstring, "Paced hellos"); the first repeat comes after the handshake's period
HELLO_EVERY_MAX_S = 1.0


def zenoh_config(listen: list[str], connect: list[str], round_timeout_s: float | None = None,
                 shared_memory: bool = False):
    """A peer-mode Zenoh config: no multicast scouting, no gossip, explicit endpoints; with
    ``round_timeout_s``, the lease and the longest blocked put of :func:`link_timeouts`.

    ``shared_memory`` (the team option of that name, off by default): Zenoh's shared-memory
    transport between the sessions of one host, on by default in Zenoh 1.x. Each session
    then keeps a pool (16 MB by default) and passes messages of 3 kB or more through it; on a
    robot process that pool, and what its neighbours' messages map, was most of its private
    memory, growing with its neighbours (``bench/team_memory.py``), for messages that are a
    few MB per stage. Between robots on separate hosts it is never used."""
    import zenoh

    doc = {
        "mode": "peer",
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "listen": {"endpoints": list(listen)},
        "connect": {"endpoints": list(connect),
                    "retry": {"period_init_ms": 100, "period_max_ms": 1000,
                              "period_increase_factor": 2}},
        "transport": {"shared_memory": {"enabled": bool(shared_memory)}},
    }
    if round_timeout_s is not None:
        lease_s, block_s = link_timeouts(round_timeout_s)
        doc["transport"]["link"] = {"tx": {
            "lease": int(lease_s * 1000),
            "queue": {"congestion_control": {"block": {"wait_before_close":
                                                           int(block_s * 1e6)}}}}}
    return zenoh.Config.from_json5(json.dumps(doc))


def open_session(listen: list[str], connect: list[str], who: str,
                 round_timeout_s: float | None = None, shared_memory: bool = False):
    """Open a Zenoh session (:func:`zenoh_config`); a listen endpoint that cannot be bound is
    one InputError line."""
    import zenoh

    try:
        return zenoh.open(zenoh_config(listen, connect, round_timeout_s, shared_memory))
    except zenoh.ZError as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else "zenoh error"
        # Zenoh's messages carry the paths of its Rust sources: not the user's concern
        msg = re.sub(r"(\s+at)?\s+[^\s\]]*(\.cargo/|\.rs:)[^\s\]]*", "", msg)
        msg = re.sub(r"(\s+at)+\s*$", "", msg).strip(" .") or "zenoh error"
        ep = listen[0] if listen else "?"
        low = msg.lower()
        if "in use" in low:
            raise InputError(f"{who}: cannot listen on {ep}: the port is in use (another "
                             f"robot or program holds it): {msg}") from None
        if "assign requested address" in low or "not available" in low:
            raise InputError(f"{who}: cannot listen on {ep}: that address is not one of this "
                             f"host's (give one of its own, e.g. 127.0.0.1): {msg}") from None
        if "bind" in low or "listen" in low:
            raise InputError(f"{who}: cannot listen on {ep}: {msg}") from None
        raise InputError(f"{who}: cannot open a Zenoh session on {ep}: {msg}") from None


class ZenohTransport(RoundEndpoint):
    """Robot ``robot_id`` of ``team`` talking to its neighbours over Zenoh.

    Parameters
    ----------
    team : pipeline.team.teamfile.Team
    robot_id : int
    drop_prob : float in [0, 1) — loss injected on outgoing algorithm messages
    seed : int — seed of the drops (combined with the robot id)
    round_timeout_s : float — silence (no packet, no beat) after which a neighbour is
        written off (``silent``)
    round_limit_s : float — longest one round waits for a neighbour that beats but sends
        nothing (then ``limit``)
    shared_memory : bool — Zenoh's shared memory with the sessions of this host
        (:func:`zenoh_config`)
    beat_s : float or None — period of the liveness beats (None: :func:`beat_period` of
        ``round_timeout_s``)
    log : callable(str) or None — progress lines (default: stderr)

    Attributes
    ----------
    written_off : dict[int, str] — neighbours written off and why (module docstring)
    silent : set[int] — the same neighbours (what the robot code asks)
    """

    def __init__(self, team, robot_id: int, *, drop_prob: float = 0.0, seed: int = 0,
                 round_timeout_s: float = 30.0, round_limit_s: float = 600.0,
                 shared_memory: bool = False, beat_s: float | None = None,
                 log=None) -> None:
        self.team = team
        self.robot_id = int(robot_id)
        self.neighbours = frozenset(team.neighbours(self.robot_id))
        self.round = 0
        self.drop_prob = float(drop_prob)
        self.lossy = False  # set by the robot when its consistency stage starts
        self._rng = np.random.default_rng([int(seed), 7, self.robot_id])
        self.round_timeout_s = float(round_timeout_s)
        self.round_limit_s = float(round_limit_s)
        self.written_off: dict[int, str] = {}
        self._tell: dict[int, float] = {}  # written-off neighbour -> last gone notice sent
        self._log = log or (lambda s: print(s, file=sys.stderr, flush=True))
        self.silent: set[int] = set()
        self._out: dict[int, list[tuple[str, dict]]] = {k: [] for k in self.neighbours}
        self._packets: dict[tuple[int, int], tuple[dict, list]] = {}
        self._hello: dict[int, bool] = {}
        # this process's own mark, sent with every hello, and the first heard from each
        # neighbour: a hello of another mark is a new process of that robot (module
        # docstring, "A neighbour started again")
        self.incarnation = os.urandom(8).hex()
        self._inc: dict[int, str] = {}
        # the team-wide settings of this robot's team file, sent with every hello; a
        # neighbour's that differ are kept here and stop the handshake (see handshake)
        self._terms = team.shared_terms()
        self._other_terms: dict[int, dict] = {}
        self._started = False  # the start handshake is over (hellos are answered)
        self._cv = threading.Condition()
        self._heard: dict[int, float] = {}
        self.beat_s = beat_period(round_timeout_s) if beat_s is None else float(beat_s)
        self._stop = threading.Event()
        self.messages = self.bytes = self.dropped = 0
        self.wire_bytes = self.wire_packets = 0
        # per neighbour: message bytes counted (as the simulator counts) and packet bytes
        # handed to Zenoh (what the namespace rig compares with the cable's counters)
        self.bytes_to = {k: 0 for k in self.neighbours}
        self.wire_bytes_to = {k: 0 for k in self.neighbours}
        self.messages_by_kind: dict[str, int] = {}
        self.bytes_by_kind: dict[str, int] = {}
        self.wait_s = 0.0
        self.resent = self.asked = 0
        self._kept: dict[int, dict[int, bytes]] = {k: {} for k in self.neighbours}
        self._asked_at: dict[int, float] = {}
        self.send_s = 0.0  # seconds the round packets' puts blocked (a full queue: slow link)
        # each link opened from one end, the higher id (module docstring)
        connect = [team.endpoint(k) for k in sorted(self.neighbours) if k < self.robot_id]
        if team.observer:
            connect.append(team.observer)
        self.session = open_session([team.endpoint(self.robot_id)], connect,
                                    f"robot {self.robot_id}", self.round_timeout_s,
                                    shared_memory)
        name = team.name
        # one subscriber per kind for every neighbour (``*`` the sender): each Python callback
        # of a subscriber runs on a thread of its own (module docstring, "Threads"); what
        # does not come from a neighbour is ignored (_from)
        self._subs = [self.session.declare_subscriber(key(name, what, "*", self.robot_id), on)
                      for what, on in (("round", self._on_packet), ("hello", self._on_hello),
                                       ("alive", self._on_beat), ("gone", self._on_gone),
                                       ("again", self._on_again))]
        import zenoh

        # round packets must never be dropped by Zenoh itself (its default under congestion
        # is to drop): the round clock relies on every packet arriving
        self._pubs = {k: self.session.declare_publisher(
            key(name, "round", self.robot_id, k),
            congestion_control=zenoh.CongestionControl.BLOCK)
            for k in sorted(self.neighbours)}
        # at most SENDER_THREADS senders, neighbour k always served by the same one (its
        # packets stay in order): a put into a slow link's full queue blocks the neighbours of
        # that sender only (module docstring, "Threads")
        order = sorted(self.neighbours)
        self._senders = [threading.Thread(target=self._sender, args=(j,), daemon=True)
                         for j in range(min(SENDER_THREADS, len(order)))]
        self._sendq = [queue.SimpleQueue() for _ in self._senders]
        self._sender_of = {k: n % SENDER_THREADS for n, k in enumerate(order)}
        for t in self._senders:
            t.start()
        self._beat_pubs = {k: self.session.declare_publisher(
            key(name, "alive", self.robot_id, k)) for k in sorted(self.neighbours)}
        self._beater = threading.Thread(target=self._beat, daemon=True)
        self._beater.start()
        # a robot's liveliness token vanishes as soon as its session does (process killed:
        # the kernel closes its sockets), which its neighbours hear within milliseconds
        self._left: set[int] = set()
        self._left_at: dict[int, float] = {}  # when each neighbour's token was heard to go
        self._token = self.session.liveliness().declare_token(key(name, "live", self.robot_id))
        self._subs.append(self.session.liveliness().declare_subscriber(
            key(name, "live", "*"), self._on_liveliness))

    def _from(self, sample, at: int) -> int | None:
        """The robot id at chunk ``at`` of ``sample``'s key expression when it is a
        neighbour's, else None (a subscriber hears ``*``: every sender)."""
        try:
            k = int(str(sample.key_expr).split("/")[at])
        except (ValueError, IndexError):
            return None
        return k if k in self.neighbours else None

    def _on_liveliness(self, sample) -> None:
        """A neighbour's own token gone: its session closed."""
        import zenoh

        self._ended(sample, zenoh.SampleKind.DELETE)

    def _ended(self, sample, kind) -> None:
        """The neighbour ``sample`` names has ended, if the sample is of ``kind``."""
        if sample.kind != kind:
            return
        k = self._from(sample, -1)
        if k is None:
            return
        with self._cv:
            self._left.add(k)
            self._left_at.setdefault(k, time.monotonic())
            self._cv.notify_all()

    def _ask_ended(self) -> None:
        """Ask the sessions this robot reaches for the launcher's ``ended`` tokens (a
        liveliness query, answered within :data:`ENDED_ASK_S`; :class:`pipeline.team.launcher.
        Observer`): a neighbour's process that ended before this robot heard its own token
        never shows one to vanish. A query rather than a subscriber: a subscriber's interest
        misses a launcher this robot's link reached only after it was declared."""
        import zenoh

        with contextlib.suppress(Exception):
            for reply in self.session.liveliness().get(key(self.team.name, "ended", "*"),
                                                       timeout=ENDED_ASK_S):
                if reply.ok is not None:
                    self._ended(reply.ok, zenoh.SampleKind.PUT)

    def _beat(self) -> None:
        """Beats to the neighbours still counted on; ``gone`` notices to those written off
        that were heard since the last notice (at most one per beat period each)."""
        while not self._stop.wait(self.beat_s):
            with self._cv:
                beat = [k for k in self._beat_pubs if k not in self.written_off]
                now = time.monotonic()
                tell = [k for k, t in self._tell.items()
                        if self._heard.get(k, -1.0) >= t and now - t >= self.beat_s]
                for k in tell:
                    self._tell[k] = now
            try:
                for k in beat:
                    self._beat_pubs[k].put(b"1")
                for k in tell:
                    self._say_gone(k)
            except Exception:  # noqa: BLE001 - the session is closing
                return

    def _queue(self, k: int, data: bytes) -> None:
        """Queue a round packet for neighbour ``k`` to its sender (never blocks)."""
        self._sendq[self._sender_of[k]].put((k, data))

    def _sender(self, j: int) -> None:
        """Sender ``j``: hand the round packets of its neighbours to Zenoh, each neighbour's in
        the order they were queued; ``None`` ends it."""
        q = self._sendq[j]
        while True:
            item = q.get()
            if item is None:
                return
            k, data = item
            if k in self.written_off:
                continue
            t_put = time.monotonic()
            try:
                self._pubs[k].put(data)
            except Exception:  # noqa: BLE001 - the session is closing: its other neighbours'
                continue  # puts fail too, and close() ends this sender
            with self._cv:
                self.send_s += time.monotonic() - t_put

    def _say_gone(self, k: int) -> None:
        self.session.put(key(self.team.name, "gone", self.robot_id, k), b"1")

    def _on_beat(self, sample) -> None:
        k = self._from(sample, -2)
        if k is None:
            return
        with self._cv:
            self._heard[k] = time.monotonic()

    def _on_gone(self, sample) -> None:
        k = self._from(sample, -2)
        if k is None:
            return
        with self._cv:
            if k not in self.written_off:
                self._write_off(k, "told")
                self._tell[k] = time.monotonic()  # it knows: no notice back
            self._cv.notify_all()

    _WHY = {"closed": "its Zenoh session closed",
            "told": "it wrote this robot off",
            "limit": "the round waited round_limit_s for it",
            "start": "no answer to the start handshake"}

    def _write_off(self, k: int, why: str) -> None:
        """Stop counting on neighbour ``k`` (caller holds ``_cv``); tell it, once now and
        again whenever it is heard later (by the beat thread)."""
        if k in self.written_off:
            return
        self.written_off[k] = why
        self.silent.add(k)
        self._tell[k] = float("-inf")  # the beat thread's next pass sends the first notice
        text = self._WHY.get(why, f"nothing from it for {self.round_timeout_s:g} s")
        self._log(f"robot {self.robot_id}: robot {k} written off in round {self.round} "
                  f"({why}: {text})")

    def outcome(self) -> str:
        """How this robot ended (module docstring): ``done``, ``cut``, ``partitioned`` or
        ``gave-up``."""
        why = set(self.written_off.values())
        if not why:
            return "done"
        if "limit" in why:
            return "gave-up"
        if why & {"silent", "told", "start"}:
            return "partitioned"
        return "cut"

    # --- callbacks (Zenoh threads) --------------------------------------------------------
    def _on_packet(self, sample) -> None:
        try:
            header, msgs = decode_packet(sample.payload.to_bytes())
        except WireError as exc:
            self._log(f"robot {self.robot_id}: dropped a malformed packet on "
                      f"{sample.key_expr}: {exc}")
            return
        src = int(header["src"])
        if src not in self.neighbours:  # the subscriber hears every sender (_from)
            return
        with self._cv:
            self._heard[src] = time.monotonic()
            if src not in self.written_off:  # a written-off robot's packets are ignored
                self._packets[(src, int(header["round"]))] = (header, msgs)
            self._cv.notify_all()

    def _on_again(self, sample) -> None:
        """A neighbour asks for this robot's packet of a round again (module docstring)."""
        k = self._from(sample, -2)
        try:
            r = int(sample.payload.to_bytes())
        except ValueError:
            return
        if k is None:
            return
        with self._cv:
            data = self._kept.get(k, {}).get(r)
            if data is None or k in self.written_off:
                return
            self.resent += 1
        self._log(f"robot {self.robot_id}: sent its round {r} packet to robot {k} again "
                  "(asked: it did not arrive)")
        self._queue(k, data)

    def _on_hello(self, sample) -> None:
        try:
            doc = json.loads(sample.payload.to_bytes())
            src, heard_me = int(doc["src"]), bool(doc["heard"])
            waiting = not bool(doc.get("done", False))
            terms = doc.get("terms")
            inc = str(doc.get("inc"))
        except (ValueError, KeyError, TypeError, AttributeError):
            return
        if src not in self.neighbours:  # the subscriber hears every sender (_from)
            return
        if isinstance(terms, dict) and terms != self._terms:
            with self._cv:
                first = src not in self._other_terms
                self._other_terms.setdefault(src, terms)
                self._cv.notify_all()
            if first:  # tell it ours at once: it may not have heard this robot yet
                try:
                    self.session.put(key(self.team.name, "hello", self.robot_id, src),
                                     json.dumps({"src": self.robot_id, "heard": False,
                                                 "done": False, "terms": self._terms, "inc": self.incarnation}))
                except Exception:  # noqa: BLE001 - the session is closing
                    pass
            return
        with self._cv:
            self._heard[src] = time.monotonic()
            if self._inc.setdefault(src, inc) != inc:  # a new process of that robot
                if src not in self.written_off:
                    self._log(f"robot {self.robot_id}: robot {src} was started again (a new "
                              "process with its id) after its first process ended: the first "
                              "is written off and the new one is told so")
                    self._write_off(src, "closed")
                self._cv.notify_all()
                return  # told ``gone`` by the beat thread: it was heard since
            self._hello[src] = self._hello.get(src, False) or heard_me
            self._cv.notify_all()
            answer = waiting and self._started and src in self.neighbours \
                and src not in self.written_off
        if answer:  # it is still in its handshake: it may have missed our last hello
            try:
                self.session.put(key(self.team.name, "hello", self.robot_id, src),
                                 json.dumps({"src": self.robot_id, "heard": True, "done": True,
                                             "terms": self._terms, "inc": self.incarnation}))
            except Exception:  # noqa: BLE001 - the session is closing
                pass

    # --- start ----------------------------------------------------------------------------
    def _check_terms(self) -> None:
        """InputError naming the first neighbour whose team file differs from this robot's in
        a team-wide setting (:meth:`pipeline.team.teamfile.Team.shared_terms`)."""
        if not self._other_terms:
            return
        k = min(self._other_terms)
        theirs = self._other_terms[k]
        keys = [x for x in sorted(set(theirs) | set(self._terms))
                if theirs.get(x) != self._terms.get(x)]
        what = "; ".join(x if x == "comm_edges" else
                         f"{x} {theirs.get(x)!r} there, {self._terms.get(x)!r} here"
                         for x in keys)
        raise InputError(f"robot {self.robot_id}: neighbour robot {k} ({self.team.endpoint(k)}) "
                         f"was started with another team file ({what}); start every robot of "
                         f"team {self.team.name!r} with the same robots, comm_edges, data.kind "
                         "and options it shares (resolution, ...)")

    def handshake(self, timeout_s: float = 60.0, period_s: float = 0.05,
                  alone: bool = False, closed_unheard: bool = False) -> float:
        """Wait until every neighbour is heard and has heard this robot; return seconds taken.

        A neighbour that starts late within ``timeout_s`` joins. One that has not answered by
        then is written off (``start``: named in the log, outcome ``partitioned``) and the robot
        runs on with the others; if it starts later it is told (``gone``) and ends alone.
        With ``alone`` (a robot with work of its own to do without neighbours: an online
        step's matching, :mod:`pipeline.team.online_match`) it runs on alone also when no
        neighbour answered, every one written off so. With ``closed_unheard`` (a team whose
        robots are never started again under the same id: the launcher's) a neighbour whose
        session closed before it was heard (its liveliness token came and went, or its
        launcher's ``ended`` token says so: its process ended while starting) is written off
        within :data:`ENDED_ASK_S` or so (``closed``), as one heard and then closed always is,
        not after ``timeout_s``; without it such a neighbour may still be started again by
        hand and join.

        Raises
        ------
        RobotMissingError
            No neighbour at all was heard within ``timeout_s`` (a wrong address is likelier
            than every neighbour being down), and not ``alone``; the message names the first.
        InputError
            A neighbour's hello carries other team-wide settings (its team file differs in the
            robots, the comm graph, the data kind or a team-only option): the two would run
            different protocols, so neither starts.
        """
        t0 = time.monotonic()
        name = self.team.name
        # per neighbour: the heard bit of the last hello sent, when it was sent, and the wait
        # before the next repeat (module docstring, "Paced hellos")
        told: dict[int, bool] = {}
        sent_at: dict[int, float] = {}
        every = {k: float(period_s) for k in self.neighbours}

        def say(done: bool = False):
            now = time.monotonic()
            for k in sorted(self.neighbours):
                with self._cv:
                    heard = k in self._hello
                due = k not in sent_at or now - sent_at[k] >= every[k]
                if not (done or heard != told.get(k) or due):
                    continue
                if due and k in sent_at and heard == told.get(k):
                    every[k] = min(2.0 * every[k], HELLO_EVERY_MAX_S)
                told[k], sent_at[k] = heard, now
                self.session.put(key(name, "hello", self.robot_id, k),
                                 json.dumps({"src": self.robot_id, "heard": heard, "done": done,
                                             "terms": self._terms, "inc": self.incarnation}))

        asked = t0  # a handshake done within ENDED_ASK_S never asks
        while True:
            say()
            if closed_unheard and time.monotonic() - asked >= ENDED_ASK_S and \
                    any(k not in self._hello for k in self.neighbours):
                self._ask_ended()
                asked = time.monotonic()
            with self._cv:
                self._check_terms()
                ok = all(self._hello.get(k, False) for k in self.neighbours
                         if k not in self.written_off)
                if not ok:
                    self._cv.wait(period_s)
                    self._check_terms()
                    # heard, then ended (or, closed_unheard, ended before it was heard)
                    for k in sorted(self._left if closed_unheard
                                    else self._left & self._hello.keys()):
                        self._write_off(k, "closed")
                    ok = all(self._hello.get(k, False) for k in self.neighbours
                             if k not in self.written_off)
                missing = sorted(k for k in self.neighbours if k not in self._hello)
                if ok:
                    self._started = True
            if ok:
                say(done=True)  # the last one tells late neighbours that they were heard
                return time.monotonic() - t0
            if time.monotonic() - t0 > timeout_s:
                missing = sorted((set(missing) | {k for k in self.neighbours
                                                  if not self._hello.get(k)}) - self.written_off.keys())
                k = missing[0]
                text = (f"neighbour robot {k} ({self.team.endpoint(k)}) did not answer within "
                        f"{timeout_s:g} s; it never started or cannot be reached")
                if len(missing) == len(self.neighbours) and not alone:
                    raise RobotMissingError(f"robot {self.robot_id}: {text}")
                # some neighbours answered: run on with them, the others written off
                for k in missing:
                    self._log(f"robot {self.robot_id}: neighbour robot {k} "
                              f"({self.team.endpoint(k)}) did not answer within {timeout_s:g} s; "
                              "it never started or cannot be reached")
                    with self._cv:
                        self._write_off(k, "start")
                with self._cv:
                    self._started = True
                return time.monotonic() - t0

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
        self.bytes_to[dst] += size
        self.messages_by_kind[kind] = self.messages_by_kind.get(kind, 0) + 1
        self.bytes_by_kind[kind] = self.bytes_by_kind.get(kind, 0) + size
        if self.lossy and self.drop_prob > 0.0 and self._rng.random() < self.drop_prob:
            self.dropped += 1
            return
        self._out[dst].append((kind, payload))

    def end_round(self, state: dict | None = None) -> tuple[list[Message], dict[int, dict]]:
        """Send this round's packets, wait for the neighbours' (see
        :meth:`RoundEndpoint.end_round`).

        Bound: returns within ``round_limit_s`` plus one beat period, whatever the neighbours
        do (the packets are queued to the neighbours' sender threads, which never hold the
        round up): a neighbour whose
        packet has not come is written off when its session closes, after ``round_timeout_s``
        of silence, when it says it wrote this robot off, or when the round has waited
        ``round_limit_s`` (module docstring, "Writing a neighbour off").
        """
        r = self.round
        sent = {}
        for k in sorted(self.neighbours):
            msgs, self._out[k] = self._out[k], []
            if k in self.silent:
                continue
            data = encode_packet({"src": self.robot_id, "dst": k, "round": r,
                                  "state": state or {}}, msgs)
            self.wire_bytes += len(data)
            self.wire_bytes_to[k] += len(data)
            self.wire_packets += 1
            sent[k] = data
            self._queue(k, data)  # never blocks: the neighbour's sender puts it
        t0 = time.monotonic()
        with self._cv:
            for k, data in sent.items():  # kept for a neighbour that asks again (two rounds)
                self._kept[k] = {r - 1: self._kept[k][r - 1]} if r - 1 in self._kept[k] else {}
                self._kept[k][r] = data
            for k in self.neighbours:
                self._heard.setdefault(k, t0)
            while True:
                waiting = [k for k in self.neighbours
                           if k not in self.silent and (k, r) not in self._packets]
                if not waiting:
                    break
                now = time.monotonic()
                for k in waiting:
                    if k in self._left and now - self._left_at.get(k, now) >= CLOSED_GRACE_S:
                        self._write_off(k, "closed")  # its last packet had time to arrive
                    elif now - self._heard[k] > self.round_timeout_s:
                        self._write_off(k, "silent")
                    elif now - t0 > self.round_limit_s:
                        self._write_off(k, "limit")
                if all(k in self.silent for k in waiting):
                    break
                for k in waiting:  # heard, but its packet of the round is late: ask again
                    if k not in self.silent and now - t0 > ASK_AFTER_S \
                            and now - self._asked_at.get(k, t0) > ASK_AFTER_S:
                        self._asked_at[k] = now
                        self.asked += 1
                        try:
                            self.session.put(key(self.team.name, "again", self.robot_id, k),
                                             str(r).encode())
                        except Exception:  # noqa: BLE001 - the session is closing
                            pass
                # bounded: every pass writes off or waits at most a beat period, and after
                # round_limit_s every neighbour still waited for is written off
                grace = [CLOSED_GRACE_S - (now - self._left_at[k]) for k in waiting
                         if k in self._left and k not in self.silent]
                self._cv.wait(max(0.01, min([self.beat_s, self.round_timeout_s, *grace])))
            got = {k: self._packets.pop((k, r)) for k in sorted(self.neighbours)
                   if k not in self.silent and (k, r) in self._packets}
            for kk in [kk for kk in self._packets if kk[1] <= r]:
                del self._packets[kk]  # late packets
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
                    send_s=round(self.send_s, 4), resent=self.resent, asked=self.asked,
                    bytes_to={str(k): v for k, v in sorted(self.bytes_to.items())},
                    wire_bytes_to={str(k): v for k, v in sorted(self.wire_bytes_to.items())},
                    silent=sorted(self.silent), outcome=self.outcome(),
                    written_off={str(k): v for k, v in sorted(self.written_off.items())})

    # --- results --------------------------------------------------------------------------
    def status(self, text: str) -> None:
        """Publish a one-line status for the observer (``started``, ``failed: ...``)."""
        self.session.put(key(self.team.name, "status", self.robot_id), text)

    def publish_result(self, data: bytes, wait_s: float = 10.0, period_s: float = 0.25) -> bool:
        """Publish the final result until the observer acknowledges it (or ``wait_s``).

        Bound: about ``wait_s`` plus one ``period_s``, plus at most ``block_s`` per put
        (:func:`link_timeouts`) when the link to the observer is full or down.
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
        """Let the senders hand over what they still hold (each at most ``block_s`` per
        packet, :func:`link_timeouts`, in parallel), then close the session."""
        for q in self._sendq:
            q.put(None)
        block_s = link_timeouts(self.round_timeout_s)[1]
        end = time.monotonic() + 2 * block_s
        for t in self._senders:
            t.join(timeout=max(0.0, end - time.monotonic()))
        self._stop.set()
        try:
            self.session.close()
        except Exception:  # noqa: BLE001 - closing a session that is already gone
            pass
