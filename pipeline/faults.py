"""Fault injection from the command line: lossy links, crashed robots, a switching topology.

The faults are properties of the simulated network (docs/DESIGN.md, "the one rule"):
:class:`FaultConfig` turns the user's flags into
:class:`~pipeline.transport.simulated.NetworkOptions` for the consistency stage and into a
per-round topology for the fusion consensus; the robots then run the fault-tolerant protocol
of :mod:`pipeline.consistency.reliable`. :func:`fault_report` writes the report's ``faults``
section: what was injected and its effect next to a fault-free run on the same input.

Flags (``add_fault_arguments``): ``--drop-prob P``, ``--delay-rounds D``, ``--crash
ROBOT@ROUND`` (repeatable), ``--switching-topology``, ``--fault-seed S``.

Delay and the robots' timers (stated): with ``--delay-rounds D`` every message spends ``D``
extra rounds in flight, so a lossless round trip takes ``2 (D + 1)`` rounds instead of 2. The
robots are configured for that link latency, as a deployment would set its timers from the
radio's: a message is retransmitted once ``2 (D + 1)`` rounds passed without its
acknowledgement (instead of 2) and a neighbour is declared lost after ``T + 4 D`` silent rounds
(``T`` = 40, :class:`~pipeline.consistency.protocols.ProtocolOptions`: the retransmissions of a
dropped message then get as many tries as without the delay), so a delay alone never makes a
live neighbour look crashed (:meth:`FaultConfig.protocol_options`). The fusion
stage's network (:meth:`fusion_transport`) has the same delay and its robots the same timers.

Time (stated): on a faulty network the simulator steps every robot in every round, and one
detection takes ``(D + 1)(d + 3)`` rounds with ``d`` the larger of the communication
graph's and the association graph's diameters (detection ends ``d + 1`` logical rounds in,
Cor. 3.6; measured: 23, 46, 253 and 2,323 rounds on a 21-camera path for ``D`` = 0, 1, 10,
100, and 66 for ``D`` = 2 on three fully connected cameras with a chain of 17 links).
:func:`check_simulated_work` refuses, before it starts, a run whose robots × rounds exceed
:data:`MAX_ROBOT_ROUNDS` (a robot-round took 17 µs of one core: 1.07 million for a
101-camera path with ``--delay-rounds 100`` in 18 s), e.g. ``--delay-rounds 100`` on a
300-camera path (9 million, some three minutes).
"""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass

import numpy as np

from pipeline import validate
from pipeline.errors import InputError

__all__ = ["FaultConfig", "add_fault_arguments", "faults_from_args", "parse_crash",
           "fault_report", "check_simulated_work", "MAX_DELAY_ROUNDS", "MAX_ROBOT_ROUNDS"]

#: Largest ``--delay-rounds``: every phase takes ``D + 1`` times its rounds, so the run's time
#: grows with ``D``; beyond this a run is refused before it starts.
MAX_DELAY_ROUNDS = 100
#: Most robots × rounds of one detection on a faulty network (module notes): about half a
#: minute of one core
MAX_ROBOT_ROUNDS = 2_000_000

_CRASH = re.compile(r"^\s*(\d+)\s*@\s*(\d+)\s*$")


@dataclass(frozen=True)
class FaultConfig:
    """Faults to inject into the simulated robot network.

    Attributes
    ----------
    drop_prob : float in [0, 1) — each message is lost independently with this probability
    delay_rounds : int in [0, MAX_DELAY_ROUNDS] — extra rounds every message spends in flight
    crash : tuple of (robot, round) — robot ``robot`` crashes at network round ``round``
        (rounds count from 0 over the whole consistency stage)
    switching_topology : bool — every communication edge is up with probability
        ``switch_p_up`` each round and at least once per ``switch_window`` rounds
        (:func:`~pipeline.transport.simulated.recurrent_topology`), for the consistency
        stage and the fusion consensus alike
    seed : int — seed of the drops and of the switching topology
    """

    drop_prob: float = 0.0
    delay_rounds: int = 0
    crash: tuple = ()
    switching_topology: bool = False
    seed: int = 0
    switch_p_up: float = 0.5
    switch_window: int = 4

    def __post_init__(self):
        _check_fields(self)
        if not 0.0 <= float(self.drop_prob) < 1.0:
            raise InputError(f"--drop-prob {self.drop_prob}: must be in [0, 1) (1 would lose "
                             "every message)")
        _check_delay(self.delay_rounds)
        robots = [int(r) for r, _ in self.crash]
        dup = sorted({r for r in robots if robots.count(r) > 1})
        if dup:
            raise InputError(f"--crash: robot {dup[0]} is given more than once; a robot crashes "
                             "once")

    @property
    def any(self) -> bool:
        """True when some fault is switched on."""
        return bool(self.drop_prob > 0 or self.delay_rounds or self.crash
                    or self.switching_topology)

    def check_robots(self, n_robots: int) -> None:
        """InputError if a crash names a robot outside ``0..n_robots-1``."""
        for r, t in self.crash:
            if not 0 <= int(r) < n_robots:
                raise InputError(f"--crash {r}@{t}: robot {r} does not exist; " + (
                    f"robots are 0..{n_robots - 1}" if n_robots else
                    "the input has no robot (no link names a camera)"))

    def topology(self, comm_edges):
        """The per-round edge function of the switching topology, or ``None``."""
        if not self.switching_topology:
            return None
        from pipeline.transport.simulated import recurrent_topology

        return recurrent_topology(comm_edges, self.switch_p_up, self.switch_window, self.seed)

    def transport(self, comm_edges, n_robots: int):
        """A simulated network with these faults (fault-free without any), for a new stage."""
        from pipeline.transport.simulated import Network

        return Network(n_robots, comm_edges, self.network_options(comm_edges, n_robots))

    def fusion_transport(self, comm_edges, survivors, start_round: int):
        """The faulty network of the fusion stage, over the robots still alive after the
        consistency stage (``survivors``, renumbered ``0..k-1`` in their order).

        The clock goes on from ``start_round`` (the consistency stage's network rounds): a
        crash at round ``r >= start_round`` happens ``r - start_round`` rounds into fusion;
        robots crashed before take no part (they are not in ``survivors``). Loss, its seed
        and the delay are the same (the robots' timers are set for the delay as in the
        consistency stage: the fusion stage's
        :class:`~pipeline.fusion.protocol.LockstepExchange` reads it from this network); a
        switching topology is drawn afresh on the survivors' links.
        """
        from pipeline.transport.simulated import Network, NetworkOptions

        survivors = np.asarray(survivors, dtype=np.int64)
        new = np.full(int(survivors.max(initial=-1)) + 1, -1, dtype=np.int64)
        new[survivors] = np.arange(len(survivors))
        e = np.asarray(comm_edges, dtype=np.int64).reshape(-1, 2)
        e = e[(e < len(new)).all(1)]
        e = new[e]
        e = e[(e >= 0).all(1)]
        crash_at = {int(new[r]): max(int(t) - int(start_round), 0) for r, t in self.crash
                    if int(r) < len(new) and new[int(r)] >= 0}
        opts = NetworkOptions(drop_probability=float(self.drop_prob),
                              delay_rounds=int(self.delay_rounds), crash_at=crash_at,
                              topology=self.topology(e), seed=int(self.seed))
        return Network(len(survivors), e, opts)

    def network_options(self, comm_edges, n_robots: int):
        """:class:`NetworkOptions` of the consistency stage, or ``None`` without faults."""
        from pipeline.transport.simulated import NetworkOptions

        self.check_robots(n_robots)
        if not self.any:
            return None
        return NetworkOptions(drop_probability=float(self.drop_prob),
                              delay_rounds=int(self.delay_rounds),
                              crash_at={int(r): int(t) for r, t in self.crash},
                              topology=self.topology(np.asarray(comm_edges).reshape(-1, 2)),
                              seed=int(self.seed))

    def protocol_options(self):
        """The robots' protocol for this network: timers set for the link latency (module
        docstring), or ``None`` (the defaults) without delay."""
        from pipeline.consistency.protocols import ProtocolOptions

        d = int(self.delay_rounds)
        return ProtocolOptions.for_delay(d) if d else None

    def as_dict(self) -> dict:
        return {"drop_prob": float(self.drop_prob), "delay_rounds": int(self.delay_rounds),
                "crash": [f"{int(r)}@{int(t)}" for r, t in self.crash],
                "switching_topology": bool(self.switching_topology),
                "switch_p_up": float(self.switch_p_up), "switch_window": int(self.switch_window),
                "seed": int(self.seed)}


def parse_crash(text: str) -> tuple[int, int]:
    """``"3@12"`` → ``(3, 12)``: robot 3 crashes at round 12.

    Raises
    ------
    InputError
        Anything but two non-negative integers joined by ``@``.
    """
    m = _CRASH.match(str(text))
    if not m:
        raise InputError(f"--crash {text!r}: expected ROBOT@ROUND with two non-negative "
                         "integers, e.g. --crash 2@15 (robot 2 crashes at round 15)")
    return int(m.group(1)), int(m.group(2))


def check_simulated_work(n_robots: int, edges, faults: FaultConfig,
                         features_per_camera=None, links=None) -> None:
    """InputError, before the run starts, when one detection on the faulty network would
    step more than :data:`MAX_ROBOT_ROUNDS` robot-rounds (module notes); ``edges`` is the
    communication graph. With ``features_per_camera`` and ``links``, ``d`` is also at least
    the association graph's diameter (lower bound): detection stops within that diameter
    plus one logical rounds (Cor. 3.6), which a chain of links can make far longer than the
    comm graph's."""
    from pipeline.commgraph import diameter_lower_bound

    D = int(faults.delay_rounds)
    d = diameter_lower_bound(int(n_robots), edges)
    what = "a communication graph"
    if links is not None and len(links):
        off = np.concatenate([[0], np.cumsum(np.asarray(features_per_camera, dtype=np.int64))])
        feats = np.stack([off[links.cam_i] + links.feat_i, off[links.cam_j] + links.feat_j], 1)
        d_links = diameter_lower_bound(int(off[-1]), feats)
        if d_links > d:
            d, what = d_links, "an association graph (links)"
    rounds = (D + 1) * (d + 3)
    if n_robots * rounds > MAX_ROBOT_ROUNDS:
        raise InputError(
            f"on a faulty network the simulator steps each of the {n_robots} robots in every "
            f"round, and one detection takes (D + 1)(d + 3) = {rounds} rounds here "
            f"(--delay-rounds {D}, {what} of diameter {d} or more): "
            f"{n_robots * rounds:,} robot-rounds, above the {MAX_ROBOT_ROUNDS:,} a run may "
            "take (half a minute); lower --delay-rounds, or run the cameras in smaller "
            "groups")


def _whole(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, np.integer))


def _check_fields(config: FaultConfig) -> None:
    """InputError naming a field of ``config`` of the wrong type: text for ``drop_prob`` failed
    in ``float()``, a crash robot of 1.5 was read as robot 1, ``'no'`` switched the topology
    on, a negative seed was taken."""
    p = config.drop_prob
    if not validate.is_number(p):
        raise InputError(f"FaultConfig drop_prob {p!r}: give a probability in [0, 1), e.g. 0.1")
    for pair in config.crash:
        if not isinstance(pair, (tuple, list)) or len(pair) != 2 \
                or not all(_whole(v) and v >= 0 for v in pair):
            raise InputError(f"FaultConfig crash {pair!r}: give (robot, round) pairs of whole "
                             "numbers >= 0, e.g. ((1, 4),)")
    if not isinstance(config.switching_topology, (bool, np.bool_)):
        raise InputError(f"FaultConfig switching_topology {config.switching_topology!r}: give "
                         "True or False")
    if not _whole(config.seed):
        raise InputError(f"FaultConfig seed {config.seed!r}: a seed must be an integer from 0 "
                         "to 2**63 - 1")
    validate.seed(config.seed, "FaultConfig seed")  # the commands' range


def _check_delay(d) -> int:
    if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or \
            not 0 <= int(d) <= MAX_DELAY_ROUNDS:
        raise InputError(f"--delay-rounds {d!r}: must be a whole number of rounds from 0 to "
                         f"{MAX_DELAY_ROUNDS}, e.g. 3")
    return int(d)


def _delay(text: str) -> int:
    try:
        d = int(str(text).strip())
    except ValueError:
        raise InputError(f"--delay-rounds {text!r}: not a whole number; give the extra rounds "
                         f"every message spends in flight, 0 to {MAX_DELAY_ROUNDS}, e.g. "
                         "3") from None
    return _check_delay(d)


def _probability(text: str) -> float:
    try:
        p = float(text)
    except ValueError:
        raise InputError(f"--drop-prob {text!r}: not a number; give a probability in [0, 1), "
                         "e.g. 0.1") from None
    if not 0.0 <= p < 1.0:
        raise InputError(f"--drop-prob {text}: must be in [0, 1)")
    return p


def add_fault_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--drop-prob``, ``--delay-rounds``, ``--crash``, ``--switching-topology`` and
    ``--fault-seed``."""
    g = parser.add_argument_group("faults (simulated robot network)")
    g.add_argument("--drop-prob", default="0", metavar="P",
                   help="each message between robots is lost with probability P in [0, 1) "
                        "(default 0)")
    g.add_argument("--delay-rounds", default="0", metavar="D",
                   help="every message between robots arrives D rounds late, 0 to "
                        f"{MAX_DELAY_ROUNDS} (default 0; the robots' timers are set for it)")
    g.add_argument("--crash", action="append", default=[], metavar="ROBOT@ROUND",
                   help="robot ROBOT crashes at network round ROUND of the consistency stage "
                        "(repeatable)")
    g.add_argument("--switching-topology", action="store_true",
                   help="communication links appear and vanish every round (each up with "
                        "probability 0.5, at least once every 4 rounds)")
    g.add_argument("--fault-seed", default="0", metavar="S",
                   help="seed of the message drops and the switching topology (default 0)")


def check_faults_for_transport(faults: FaultConfig | None, transport: str) -> None:
    """InputError when a fault of the simulated network is asked of another transport:
    ``--crash``, ``--delay-rounds`` and ``--switching-topology`` act in the simulator's
    network only (a process team is disturbed by killing, freezing or cutting off its robots);
    ``--drop-prob`` works on every transport. Checked before anything else about the faults
    is said or done."""
    if faults is not None and transport != "sim" and (
            faults.crash or faults.switching_topology or faults.delay_rounds):
        raise InputError("--crash, --delay-rounds and --switching-topology are faults of the "
                         f"simulated network (--transport sim); over {transport}, kill a robot "
                         "process instead; --drop-prob works on both")


def warn_rule_under_faults(faults: FaultConfig | None, resolution: str | None) -> str | None:
    """Warn (shown even with ``--quiet``) when a fault flag makes the chosen rule give way to
    the fault-tolerant Alg. 1 (:func:`pipeline.consistency.rules.rule_for_network`: a rule that
    is not fault-tolerant runs on a fault-free network only); returns the warning, or None."""
    from pipeline.consistency.rules import DEFAULT_RESOLUTION, rule_for_network
    from pipeline.progress import log

    if faults is None or not faults.any:
        return None
    asked = resolution or DEFAULT_RESOLUTION
    ran = rule_for_network(asked, True).name
    if ran == asked:
        return None
    flags = [flag for flag, on in (("--drop-prob", faults.drop_prob > 0),
                                   ("--delay-rounds", bool(faults.delay_rounds)),
                                   ("--crash", bool(faults.crash)),
                                   ("--switching-topology", faults.switching_topology)) if on]
    text = (f"--resolution {asked} is not fault-tolerant: with {', '.join(flags)} the robots run "
            f"the fault-tolerant Alg. 1 ({ran}) instead (the report names the rule that ran)")
    log.warning("warning: %s", text)
    return text


def faults_from_args(args) -> FaultConfig:
    """The :class:`FaultConfig` of parsed arguments; InputError on a bad value."""
    from pipeline.validate import seed as checked_seed

    seed = checked_seed(args.fault_seed, "--fault-seed")
    config = FaultConfig(drop_prob=_probability(args.drop_prob),
                         delay_rounds=_delay(args.delay_rounds),
                         crash=tuple(parse_crash(c) for c in args.crash),
                         switching_topology=bool(args.switching_topology), seed=seed)
    if seed != 0 and not (config.drop_prob > 0 or config.switching_topology):
        if getattr(args, "transport", "sim") != "sim":
            # robot processes model no switching topology (check_faults_for_transport)
            raise InputError(f"--fault-seed {seed}: it seeds the message drops, and this run has "
                             f"none (it would change nothing); over --transport {args.transport} "
                             "add --drop-prob, or drop --fault-seed")
        raise InputError(f"--fault-seed {seed}: it seeds the message drops and the switching "
                         "topology, and this run has neither (it would change nothing); add "
                         "--drop-prob or --switching-topology, or drop --fault-seed")
    return config


def fault_report(config: FaultConfig, result, fault_free=None) -> dict:
    """The report's ``faults`` section: what was injected and its effect.

    Parameters
    ----------
    config : FaultConfig
    result : ConsistencyResult — the run with faults
    fault_free : ConsistencyResult or None — the same input on a fault-free network

    Returns
    -------
    dict with ``injected`` (the config), ``protocol``, ``crashed`` (robot -> round, crashes
    that happened), ``crashed_after_close`` (those of them after the robot had confirmed the
    stage's closing phase: its links stay kept, see :mod:`pipeline.consistency.reliable`),
    ``close_round`` (network round at which the last closing phase began, or ``None``),
    ``crashes_not_reached`` (the stage ended first; a run with fusion moves those that hit
    the fusion stage to ``crashed_during_fusion``, :func:`pipeline.stages.clean_association`),
    ``robots_lost`` (robot ->
    neighbours that declared it lost), ``links_cut_robot_lost``, ``messages_dropped``,
    ``retransmissions``, ``acks``, ``heartbeats``, ``repeated_detections``, ``rounds``
    (detection, resolution and closing),
    ``messages``; with ``fault_free`` (a run of the same rule: the caller names it in
    ``fault_free_resolution``): ``extra_rounds``, ``extra_messages``,
    ``extra_links_deleted``.
    """
    st = result.stats
    f = st.get("faults", {})
    rounds = int(st["detection_rounds"] + st["resolution_rounds"] + st.get("closing_rounds", 0))
    out = {"injected": config.as_dict(), "protocol": st.get("protocol"),
           "crashed": {str(k): v for k, v in f.get("crashed", {}).items()},
           "crashed_after_close": {str(k): v
                                   for k, v in f.get("crashed_after_close", {}).items()},
           "close_round": f.get("close_round"),
           "crashes_not_reached": {str(k): v for k, v in f.get("crashes_not_reached", {}).items()},
           "robots_lost": {str(k): v for k, v in f.get("robots_lost", {}).items()},
           "links_cut_robot_lost": int(f.get("links_cut_robot_lost", 0)),
           "messages_dropped": int(f.get("dropped", 0)),
           "retransmissions": int(f.get("retransmissions", 0)),
           "acks": int(f.get("acks", 0)), "heartbeats": int(f.get("heartbeats", 0)),
           "repeated_detections": int(f.get("repeated_detections", 0)),
           "rounds": rounds, "messages": int(st["messages"])}
    if fault_free is not None:
        fs = fault_free.stats
        out["fault_free_rounds"] = int(fs["detection_rounds"] + fs["resolution_rounds"])
        out["fault_free_messages"] = int(fs["messages"])
        out["extra_rounds"] = rounds - out["fault_free_rounds"]
        out["extra_messages"] = out["messages"] - out["fault_free_messages"]
        out["extra_links_deleted"] = int(result.deleted.sum()) - int(fault_free.deleted.sum())
    return out
