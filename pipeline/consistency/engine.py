"""Driver of the distributed consistency stage: detection + resolution until conflict-free.

Implements the loop of Prop. 4.5 (Aragüés et al.): every robot runs the detection of Sec. III
(:mod:`.detection`), then the resolution of Sec. IV, Alg. 1 (:mod:`.resolution`), on what
remains, until no robot finds a conflictive feature.

One loop runs every phase (:func:`run_phase`) with one of two protocol objects
(:mod:`.protocols`: the paper's, or the fault-tolerant one). The driver only plays the clock
and the phase barrier of a synchronous system: it tells every robot that a round or a phase
begins, hands it its inbox (the protocol holds each robot's endpoint to send through), and
after the run it reads each robot's own log to report what happened. It never passes
one robot's state to another. Phase ends are decided by the simulation (a detection ends
when every robot has stopped, Prop. 3.5; a resolution when no message is in flight); a
deployment would wait the proven bounds instead (``d + 1`` and ``n + 1`` rounds).

With a fault switch of the network on, the robots run the fault-tolerant protocol of
:mod:`.reliable` (acknowledged, retransmitted messages; lockstep detection; timeouts of
``T`` rounds on silent neighbours). Then a phase ends when every robot still alive is done
(detection: stopped, every linked neighbour's ``final`` in, everything acknowledged;
resolution: everything acknowledged); a detection in which a robot lost a neighbour is run
again before any resolution. A detection that lost nobody and found no conflictive feature
is followed by the closing phase (:mod:`.reliable`, "Closing round": every robot has each
linked neighbour acknowledge a ``closing`` message); the loop ends when that phase lost
nobody, else the detection runs again. A crashed robot is simply no longer stepped (it is
dead); the survivors learn of it only from its silence.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.association import camera_offsets, check_links
from pipeline.commgraph import comm_edges_for
from pipeline.consistency import DEFAULT_RESOLUTION, RESOLUTIONS, batched, batched_evidence
from pipeline.consistency.evidence import equip, run_evidence_resolution
from pipeline.consistency.linklog import merge_link_logs
from pipeline.consistency.protocols import (
    CLOSING,
    DETECTION,
    RESOLUTION,
    ProtocolOptions,
    end_phase,
    make_protocol,
)
from pipeline.consistency.robot import Robot
from pipeline.errors import InputError
from pipeline.progress import rounds_bar
from pipeline.transport import Transport
from pipeline.transport.simulated import Network, NetworkOptions
from pipeline.types import Links

__all__ = [
    "ConsistencyResult",
    "resolve_conflicts",
    "build_robots",
    "run_phase",
    "detect_once",
    "Detection",
]


@dataclass
class ConsistencyResult:
    """What the distributed stage did to every input link.

    Attributes
    ----------
    links : Links — the input links, ``(L,)``
    deleted : ndarray, (L,) bool
    reason : ndarray, (L,) str — ``'resolution'`` for a link cut by Alg. 1, ``'robot-lost'`` for a
        link cut because the robot at its other end was declared lost, ``''`` if kept
    iteration : ndarray, (L,) int — detection/resolution iteration that cut it (1-based), -1 if kept
    round : ndarray, (L,) int — resolution round of that iteration in which the receiver of the
        request cut it (1-based), -1 if kept
    case : ndarray, (L,) str — ``'b'`` or ``'c'`` (Alg. 1) or ``'evidence'`` for a link cut by resolution, ``''``
        otherwise
    component : ndarray, (m_total,) int64 — component ``C_q`` built by Alg. 1 for every feature
        (``q`` = global id of its root feature), -1 for features never assigned
    track_label : ndarray, (m_total,) int64 — each robot's own name for the track of each of
        its features (:meth:`Robot.final_tracks`), -1 outside tracks
    stats : dict — ``iterations`` (detection + resolution passes that found conflicts; a
        last detection that finds none ends the loop and is counted in the rounds),
        ``detection_rounds``, ``resolution_rounds`` (totals over all passes),
        ``closing_rounds`` (total of the closing phases; reliable protocol only),
        ``per_iteration`` (one dict per detection: ``detection_rounds``, ``t_stop`` (n,) the
        round each robot stopped (Prop. 3.5), ``conflictive_features``, ``conflictive_sets``,
        ``resolution_rounds``, ``last_assignment_round``, ``messages``, ``bytes``),
        ``messages``, ``bytes``, ``messages_by_kind``, ``bytes_by_kind``,
        ``max_robot_memory_bytes`` (peak over robots and rounds of :meth:`Robot.memory_bytes`),
        ``asymmetric_links`` (links between two surviving robots deleted at one end only),
        ``deleted_links``, ``protocol`` (``paper`` or ``reliable``), ``resolution`` (the rule
        that cut: ``paper`` or ``evidence``), ``survivors`` (n,) bool
        (robots alive at the end), and ``faults``: what the network injected and its effect
        (``dropped`` messages, ``crashed`` robots with their crash round,
        ``crashed_after_close`` (those of them that crashed after the last closing phase
        began and were not declared lost: they acknowledged every ``closing`` sent to them,
        so their links were kept by the close), ``close_round`` (network round at which the
        last closing phase began, ``None`` without one), ``robots_lost``
        (robot -> neighbours that declared it lost), ``links_cut_robot_lost``,
        ``retransmissions``, ``acks``, ``heartbeats``, ``repeated_detections``)
    """

    links: Links
    deleted: np.ndarray
    reason: np.ndarray
    iteration: np.ndarray
    round: np.ndarray
    case: np.ndarray
    component: np.ndarray
    stats: dict = field(default_factory=dict)
    track_label: np.ndarray | None = None

    def kept(self) -> Links:
        """The links that survived, ``Links`` of length ``(~deleted).sum()``."""
        return self.links.subset(~self.deleted)


def build_robots(features_per_camera, links: Links) -> tuple[list[Robot], list[np.ndarray]]:
    """Hand every robot its own associations (what its matching produced).

    Returns
    -------
    robots : list[Robot], (n,)
    link_index : list of (L_i,) int64 — for the report only: the input link behind each row
        of robot ``i``'s link table (the robot itself never sees it)
    """
    fpc = np.asarray(features_per_camera, dtype=np.int64)
    n = fpc.shape[0]
    L = len(links)
    idx = np.arange(L)
    # each link appears at both ends: (robot, neighbour, own feature, their feature, link)
    owner = np.concatenate([links.cam_i, links.cam_j])
    nbr = np.concatenate([links.cam_j, links.cam_i])
    r = np.concatenate([links.feat_i, links.feat_j])
    s = np.concatenate([links.feat_j, links.feat_i])
    li = np.concatenate([idx, idx])
    span = int(fpc.max(initial=0)) + 1
    if n * n * span < 2**62:  # one int64 key: faster than a three-key lexsort
        key = (owner.astype(np.int64) * n + nbr) * span + s
        # the keys are distinct when no feature is linked twice to one camera (Assumption
        # 2.2): any sort gives the stable order then
        order = np.argsort(key)
        if (key[order][1:] == key[order][:-1]).any():
            order = np.argsort(key, kind="stable")
    else:
        order = np.lexsort((s, nbr, owner))
    owner, nbr, r, s, li = owner[order], nbr[order], r[order], s[order], li[order]
    bounds = np.searchsorted(owner, np.arange(n + 1))
    robots, link_index = [], []
    for i in range(n):
        a, b = bounds[i], bounds[i + 1]
        robots.append(Robot(i, fpc, nbr[a:b], r[a:b], s[a:b]))
        link_index.append(li[a:b])  # Robot keeps the (nbr, s) order given here
    return robots, link_index


def run_phase(robots: list[Robot], network: Transport, protocol, phase: str, iteration: int = 0,
              max_rounds: int | None = None, on_round=None) -> dict:
    """One phase (``detection`` or ``resolution``) on all robots: the one loop of the stage.

    Round 0: every robot of the protocol's team starts the phase. Then, round after round,
    the network delivers and every robot of the team (those still alive, for the reliable
    protocol) takes one step on its inbox, until the protocol says the phase is over.

    ``on_round`` (callable ``(round) -> None`` or None) is told each round (progress).

    Returns
    -------
    dict — ``rounds``, ``start_round`` (network round of round 0), ``lost`` (some robot
    declared a neighbour lost); detection: ``t_stop`` (n,) the round each robot stopped
    (Prop. 3.5), ``conflictive_features``; resolution: ``conflictive_sets`` (sets rooted,
    eq. 10); closing: nothing more
    """
    start_round = int(network.round)
    live = protocol.team(robots)
    rooted = sum(protocol.start(phase, rb, iteration) for rb in live)
    cap = protocol.max_rounds(phase, robots) if max_rounds is None else max_rounds
    t = 0
    while True:
        live = protocol.team(live)
        if protocol.done(phase, live):
            break
        network.end_round()
        t += 1
        if on_round is not None:
            on_round(t)
        for rb in protocol.team(live):
            protocol.step(phase, rb, network.inbox(rb.id), t)
        if t > cap:
            raise RuntimeError(f"{phase} did not end within {cap} rounds")
    end_phase(phase, robots)
    out = dict(rounds=t, start_round=start_round, lost=protocol.lost_in_phase(live))
    if phase == DETECTION:
        out.update(t_stop=np.array([rb.t_stop for rb in robots], dtype=np.int64),
                   conflictive_features=int(sum(int(rb.conflictive.sum()) for rb in live)))
    elif phase == RESOLUTION:
        out.update(conflictive_sets=int(rooted))
    return out


@dataclass
class Detection:
    """One detection (Sec. III) run by :func:`detect_once`.

    Attributes
    ----------
    robots : list[Robot] — after the detection (``X``, ``conflictive``, ``t_stop``, ...)
    stats : dict — as returned by :func:`run_phase`
    network : Transport — the network it ran on (counters)
    protocol : the protocol object it ran
    """

    robots: list[Robot]
    stats: dict
    network: Transport
    protocol: object


def detect_once(features_per_camera, links: Links, comm_edges=None,
                network_options: NetworkOptions | None = None,
                protocol: ProtocolOptions | None = None, *, network: Transport | None = None,
                max_rounds: int | None = None, engine: str = "auto") -> Detection:
    """Run one detection (Sec. III) with protocol P on a fresh team; for benches and tests.

    Parameters
    ----------
    features_per_camera, comm_edges, links, network_options, protocol
        As in :func:`resolve_conflicts`.
    network : Transport or None — a network to run on instead of a new simulated one
    max_rounds : int or None — cap of the phase (default: the protocol's)
    engine : ``auto``, ``batched`` or ``per-robot`` — as in :func:`resolve_conflicts`

    Returns
    -------
    Detection
    """
    fpc = np.asarray(features_per_camera, dtype=np.int64).reshape(-1)
    robots, _ = build_robots(fpc, links)
    if network is None:
        network = Network(fpc.shape[0], comm_edges_for(fpc, links, comm_edges), network_options)
    proto = make_protocol(protocol, network, fpc)
    if _use_batched(engine, network, proto):
        stats = batched.run_detection(robots, network, proto, 1, max_rounds=max_rounds)
    else:
        stats = run_phase(robots, network, proto, DETECTION, iteration=1, max_rounds=max_rounds)
    return Detection(robots, stats, network, proto)


ENGINES = ("auto", "batched", "per-robot")


def _use_batched(engine: str, network: Transport, protocol) -> bool:
    """Whether to evaluate the robots in batch (:mod:`.batched`): ``auto`` where it applies."""
    if engine not in ENGINES:
        raise InputError(f"engine {engine!r}: choose one of {', '.join(ENGINES)}")
    applies = batched.batched_applies(network, protocol)
    if engine == "batched" and not applies:
        raise InputError("engine 'batched' needs the in-process network with no fault and the "
                         "paper's protocol with delta messages; use engine 'auto' or "
                         "'per-robot'")
    return applies and engine != "per-robot"


def resolve_conflicts(features_per_camera, comm_edges, links: Links,
                      network_options: NetworkOptions | None = None,
                      protocol: ProtocolOptions | None = None,
                      resolution: str = DEFAULT_RESOLUTION,
                      link_weight=None, keypoints=None, projections=None,
                      engine: str = "auto") -> ConsistencyResult:
    """Make the association graph conflict-free with robots that only talk to neighbours.

    Parameters
    ----------
    features_per_camera : array_like, (n,) int
        ``m_i`` of every camera (public knowledge of all robots).
    comm_edges : array_like, (E, 2) int or None
        Communication graph; ``None``: cameras that share a link are neighbours.
    links : Links, (L,)
        The local associations ``A_ij`` (Assumptions 2.1–2.3, checked).
    network_options : NetworkOptions or None
        Fault switches of the simulated network (all off by default).
    protocol : ProtocolOptions or None
        The robots' protocol: the paper's (default on a fault-free network) or the
        fault-tolerant one of :mod:`.reliable` (default when a fault switch is on).

    resolution : ``paper`` or ``evidence`` (default :data:`.DEFAULT_RESOLUTION`)
        ``paper``: Alg. 1. ``evidence``: the flood-and-solve rule of :mod:`.evidence` (on a
        fault-free network; with a fault switch on, the fault-tolerant Alg. 1 is used and
        ``stats['resolution']`` says so).
    link_weight : array_like (L,) float or None
        ``evidence`` only: local evidence of each link (:mod:`pipeline.link_evidence`);
        ``None``: the Lowe-ratio term of ``links.quality``.
    keypoints : list of (m_i, 2) arrays or None
        ``evidence`` only: each robot's keypoints (for the geometric test).
    projections : list of (3, 4) arrays (or None entries) or None
        ``evidence`` only: each robot's ``K [R | t]``; the geometric test needs all of a set's.
    engine : ``auto``, ``batched`` or ``per-robot``
        How the simulator evaluates the robots' rounds. ``per-robot``: every robot steps on
        its inbox, one by one (the code robots run under faults and over a middleware).
        ``batched``: the same updates, all robots' detection rows in one sparse product per
        round (:mod:`.batched`), Alg. 1's rounds on the link tables stacked
        (:mod:`.batched_resolution`), the
        evidence rule's flood in one vectorized step per round and each set solved once
        (:mod:`.batched_evidence`); same results, rounds, messages, bytes and memory; it
        needs the paper's protocol with delta messages on a fault-free network. ``auto``:
        batched exactly there.

    Returns
    -------
    ConsistencyResult

    Raises
    ------
    InputError
        Links break Assumptions 2.1–2.3, or join cameras that are not neighbours.

    Notes
    -----
    With ``evidence``, one pass suffices: it takes at most ``diam(C) + 1 ≤ d + 1`` rounds
    and leaves the graph conflict-free, so the loop ends with the next detection. Per
    iteration of Alg. 1: detection takes at most ``d + 1`` rounds (Cor. 3.6), resolution at most
    ``n + 1`` (Thm. 4.3 (i) plus the delivery of the last rejects); every conflictive set
    shrinks by ``≥ 4`` features per iteration, so the loop ends (Prop. 4.5). With the
    fault-tolerant protocol these bounds hold in *logical* rounds of detection; network rounds
    grow with the loss, and each crash costs at most ``T`` rounds of waiting plus one repeated
    detection per round in which a neighbour was declared lost.

    References
    ----------
    R. Aragüés, E. Montijano, C. Sagués, "Consistent data association in multi-robot systems
    with limited communications", RSS 2010 — Secs. III–IV, Alg. 1.

    Examples
    --------
    >>> from pipeline.types import Links
    >>> links = Links([0, 0, 1, 2], [0, 0, 0, 0], [3, 1, 2, 3], [1, 0, 0, 0])  # paper Fig. 1
    >>> res = resolve_conflicts([1, 1, 1, 2], None, links)
    >>> int(res.deleted.sum())
    1
    """
    if resolution not in RESOLUTIONS:
        raise InputError(f"resolution {resolution!r}: choose one of {', '.join(RESOLUTIONS)}")
    fpc = np.asarray(features_per_camera, dtype=np.int64).reshape(-1)
    camera_offsets(fpc)
    check_links(links, fpc)
    edges = comm_edges_for(fpc, links, comm_edges)
    n = fpc.shape[0]
    robots, link_index = build_robots(fpc, links)
    network = Network(n, edges, network_options)
    proto = make_protocol(protocol, network, fpc)
    in_batch = _use_batched(engine, network, proto)
    reliable = proto.name == "reliable"
    # the evidence rule (pipeline.consistency.evidence) runs on a fault-free network; with
    # faults the fault-tolerant Alg. 1 is used, and stats['resolution'] says so
    use_evidence = resolution == "evidence" and not reliable
    if use_evidence:
        _equip_evidence(robots, link_index, links, link_weight, keypoints, projections)
    m_total = int(fpc.sum())

    with rounds_bar(f"consistency: {n} robots") as bar:
        per_iteration, repeated, close_round = _loop(robots, network, proto, in_batch,
                                                     use_evidence, reliable, m_total, bar)
    result = _collect(fpc, links, robots, link_index, per_iteration, network, proto, repeated,
                      close_round)
    result.stats["resolution"] = "evidence" if use_evidence else "paper"
    return result


def _loop(robots, network, proto, in_batch: bool, use_evidence: bool, reliable: bool,
          m_total: int, bar) -> tuple[list[dict], int, int | None]:
    """The loop of Prop. 4.5: detection, then resolution, until a detection finds nothing.

    Returns the per-iteration records, the repeated detections and the round of the closing
    (reliable protocol; ``None`` otherwise)."""
    n = len(robots)

    def counting(phase: str, iteration: int):
        bar.set_description_str(f"consistency ({n} robots): {phase} {iteration}", refresh=False)
        return lambda t: bar.update(1)

    per_iteration = []
    # Prop. 4.5: each set loses >= 4 features per pass; each repeated detection follows a loss
    max_iterations = m_total // 4 + 2 + (n * n if reliable else 0)
    iteration = 0
    repeated = 0
    close_round = None
    while True:
        iteration += 1
        if iteration > max_iterations:
            raise RuntimeError(f"conflicts remain after {max_iterations} iterations (Prop. 4.5 bound)")
        c0 = network.counters()
        on_round = counting(DETECTION, iteration)
        if in_batch:
            det = batched.run_detection(robots, network, proto, iteration, on_round=on_round)
        else:
            det = run_phase(robots, network, proto, DETECTION, iteration, on_round=on_round)
        rec = dict(iteration=iteration, detection_rounds=det["rounds"], t_stop=det["t_stop"],
                   conflictive_features=det["conflictive_features"], conflictive_sets=0,
                   resolution_rounds=0, start_round=int(c0.get("round", 0)))
        if det.get("lost"):
            # a robot lost a neighbour during this detection: its result is not trusted
            rec.update(_delta(c0, network.counters()), repeated=True)
            per_iteration.append(rec)
            repeated += 1
            continue
        if det["conflictive_features"] == 0:
            if proto.closing:
                # every linked neighbour confirms it is alive (reliable.py, "Closing round")
                clo = run_phase(robots, network, proto, CLOSING, iteration,
                                on_round=counting(CLOSING, iteration))
                rec.update(closing_rounds=clo["rounds"], close_round=clo["start_round"])
                if clo["lost"]:
                    # a neighbour found dead at the close: detect again without it
                    rec.update(_delta(c0, network.counters()), repeated=True)
                    per_iteration.append(rec)
                    repeated += 1
                    continue
                close_round = clo["start_round"]
            rec.update(_delta(c0, network.counters()))
            per_iteration.append(rec)
            break
        on_round = counting(RESOLUTION, iteration)
        if use_evidence:
            run_pass = batched_evidence.run_evidence_resolution if in_batch else \
                run_evidence_resolution
            res = run_pass(robots, network, on_round=on_round)
        elif in_batch:
            res = batched.run_resolution(robots, network, proto, iteration, on_round=on_round)
        else:
            res = run_phase(robots, network, proto, RESOLUTION, iteration, on_round=on_round)
        rec.update(conflictive_sets=res["conflictive_sets"], resolution_rounds=res["rounds"],
                   last_assignment_round=int(max(
                       (int(rb.assigned_round[rb.component >= 0].max(initial=-1)) for rb in robots),
                       default=-1)))
        rec.update(_delta(c0, network.counters()))
        per_iteration.append(rec)
    return per_iteration, repeated, close_round


def _equip_evidence(robots, link_index, links: Links, link_weight, keypoints,
                    projections) -> None:
    """Hand every robot its own evidence (its rows of the inputs only)."""
    from pipeline.link_evidence import ratio_llr

    L = len(links)
    w = ratio_llr(1.0 - links.quality) if link_weight is None else \
        np.asarray(link_weight, dtype=np.float64).reshape(-1)
    if w.shape[0] != L:
        raise InputError(f"link_weight has {w.shape[0]} entries for {L} links")
    for rb, li in zip(robots, link_index, strict=True):
        kp = np.zeros((rb.m, 2)) if keypoints is None else keypoints[rb.id]
        P = None if projections is None else projections[rb.id]
        equip(rb, w[li], kp, P)


def _delta(c0: dict, c1: dict) -> dict:
    return dict(messages=c1["messages"] - c0["messages"], bytes=c1["bytes"] - c0["bytes"])


def _collect(fpc, links: Links, robots: list[Robot], link_index: list[np.ndarray],
             per_iteration: list[dict], network: Network, protocol,
             repeated: int = 0, close_round: int | None = None) -> ConsistencyResult:
    """Read every robot's own log into per-link arrays (reporting only)."""
    L = len(links)
    survivors = np.array([network.alive(rb.id) for rb in robots], dtype=bool)
    d = merge_link_logs(L, [(li, rb.link_alive, rb.deleted_case, rb.deleted_round,
                             rb.deleted_iteration)
                            for rb, li in zip(robots, link_index, strict=True)])
    deleted, reason, iteration, round_, case = (d[k] for k in ("deleted", "reason", "iteration",
                                                               "round", "case"))
    ends_deleted, robot_lost = d["ends_deleted"], d["robot_lost"]
    component = np.concatenate([rb.component for rb in robots]) if robots else np.zeros(0, np.int64)
    track_label = np.concatenate([rb.final_tracks() for rb in robots]) if robots else \
        np.zeros(0, np.int64)
    cnt = network.counters()
    both_alive = survivors[links.cam_i] & survivors[links.cam_j] if L else np.zeros(0, dtype=bool)
    extra = protocol.counters()
    lost_by = [protocol.lost_neighbours(rb.id) for rb in robots]
    injected = network.injected_faults()
    crash_rounds = injected["crash_rounds"]
    faults = dict(
        drop_probability=float(injected["drop_probability"]),
        switching_topology=bool(injected["switching_topology"]),
        dropped=int(cnt["dropped"]),
        crashed={i: r for i, r in sorted(crash_rounds.items()) if not survivors[i]},
        crashes_not_reached={i: r for i, r in sorted(crash_rounds.items()) if survivors[i]},
        robots_lost={int(k): sorted(int(i) for i, lost in enumerate(lost_by) if k in lost)
                     for k in sorted({k for lost in lost_by for k in lost})},
        links_cut_robot_lost=int(robot_lost.sum()),
        retransmissions=extra["retransmissions"],
        acks=extra["acks"],
        heartbeats=extra["heartbeats"],
        repeated_detections=int(repeated),
        rounds=int(network.round),
    )
    stats = dict(
        iterations=sum(1 for p in per_iteration
                       if p["conflictive_features"] > 0 and not p.get("repeated")),
        detection_rounds=int(sum(p["detection_rounds"] for p in per_iteration)),
        resolution_rounds=int(sum(p["resolution_rounds"] for p in per_iteration)),
        per_iteration=per_iteration,
        messages=cnt["messages"], bytes=cnt["bytes"],
        messages_by_kind=cnt["messages_by_kind"], bytes_by_kind=cnt["bytes_by_kind"],
        max_robot_memory_bytes=int(max((network.peak_memory(rb.id) for rb in robots), default=0)),
        asymmetric_links=int(((ends_deleted == 1) & both_alive).sum()),
        deleted_links=int(deleted.sum()),
        protocol=protocol.name,
        survivors=survivors,
        faults=faults,
    )
    if protocol.closing:
        stats["closing_rounds"] = int(sum(p.get("closing_rounds", 0) for p in per_iteration))
        faults.update(close_round=close_round, crashed_after_close={
            i: r for i, r in faults["crashed"].items()
            if close_round is not None and r > close_round
            and not any(i in lost for lost in lost_by)})
    return ConsistencyResult(links=links, deleted=deleted, reason=reason, iteration=iteration,
                             round=round_, case=case, component=component, stats=stats,
                             track_label=track_label)
