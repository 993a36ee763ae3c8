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

from dataclasses import dataclass

import numpy as np

from pipeline.association import camera_offsets, check_links
from pipeline.commgraph import comm_edges_for
from pipeline.consistency.engines import batched
from pipeline.consistency.engines.phases import run_phase
from pipeline.consistency.evidence import equip
from pipeline.consistency.protocols import (
    CLOSING,
    DETECTION,
    RESOLUTION,
    ProtocolOptions,
    make_protocol,
)
from pipeline.consistency.result import ConsistencyResult, result_from_logs
from pipeline.consistency.robot import Robot
from pipeline.consistency.rules import DEFAULT_RESOLUTION, get_rule, rule_for_network
from pipeline.errors import InputError
from pipeline.progress import rounds_bar
from pipeline.transport import Transport
from pipeline.transport.simulated import Network, NetworkOptions
from pipeline.types import Links
from pipeline.validate import is_number

__all__ = [
    "ConsistencyResult",
    "resolve_conflicts",
    "build_robots",
    "detect_once",
    "Detection",
]



#: most features a team may declare (each robot holds arrays of the team's feature count)
MAX_FEATURES = 2**31 - 1

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
    offsets = np.concatenate([[0], np.cumsum(fpc)]).astype(np.int64)
    offsets.flags.writeable = False  # the public layout, shared by every robot
    robots, link_index = [], []
    for i in range(n):
        a, b = bounds[i], bounds[i + 1]
        robots.append(Robot(i, fpc, nbr[a:b], r[a:b], s[a:b], offsets=offsets, key_base=span))
        link_index.append(li[a:b])  # Robot keeps the (nbr, s) order given here
    return robots, link_index


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


def _feature_counts(features_per_camera) -> np.ndarray:
    """``m_i`` of every camera as int64, refused (InputError) unless whole numbers >= 0 that
    sum to at most :data:`MAX_FEATURES`."""
    fpc = np.diff(camera_offsets(features_per_camera))  # whole numbers >= 0, named if not
    if int(fpc.sum()) > MAX_FEATURES:
        raise InputError(f"features_per_camera sums to {int(fpc.sum()):,} features, above "
                         f"{MAX_FEATURES:,}: every robot holds arrays of the team's feature "
                         "count; give the counts of the features that exist (resolve renumbers "
                         "sparse ids to those present)")
    return fpc


def _check_options(network_options, protocol) -> None:
    """InputError naming options that are not :class:`NetworkOptions` / :class:`ProtocolOptions`
    (a dict of them failed with an AttributeError inside the network)."""
    for given, cls, name in ((network_options, NetworkOptions, "network_options"),
                             (protocol, ProtocolOptions, "protocol")):
        if given is not None and not isinstance(given, cls):
            raise InputError(f"{name} must be a {cls.__module__}.{cls.__name__} or None, not "
                             f"{type(given).__name__}: give {cls.__name__}(...) of its fields")


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
    if isinstance(comm_edges, Links) and not isinstance(links, Links):
        # resolve_conflicts' order (comm_edges second) was named "links must be a Links, not
        # ndarray" (or NoneType), which did not say the two were swapped
        raise InputError("detect_once takes (features_per_camera, links, comm_edges): the "
                         "links come second, unlike resolve_conflicts(features_per_camera, "
                         "comm_edges, links); swap the two arguments")
    _check_options(network_options, protocol)
    fpc = _feature_counts(features_per_camera)
    check_links(links, fpc)  # as resolve_conflicts: a self-link read as a conflict
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
                      engine: str = "auto", bundle_budget: int | None = None,
                      solve_small_sets: bool = True, gather_conflictive: bool = False,
                      gather_free: bool = False) -> ConsistencyResult:
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

    resolution : str
        A rule of :mod:`pipeline.consistency.rules` (default
        :data:`~pipeline.consistency.rules.DEFAULT_RESOLUTION`, ``evidence``): ``paper``
        (Alg. 1), ``evidence`` (the flood-and-solve rule of :mod:`.evidence`), ... A rule that
        is not fault-tolerant runs on a fault-free network; with a fault switch on, the
        fault-tolerant Alg. 1 is used and ``stats['resolution']`` says so.
    link_weight : array_like (L,) float or None
        A rule that ``needs_evidence`` only (``evidence``): local evidence of each link (:mod:`pipeline.matching.link_evidence`);
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
    bundle_budget : int or None
        ``evidence`` only: the largest set (in features) solved by its bundles; larger sets
        are solved by the distributed greedy merge on their links
        (:mod:`.evidence_stage`). ``None``: :func:`~pipeline.consistency.setlists.
        bundle_budget` of the team's size. ``stats['large_sets']`` counts the larger sets.
    solve_small_sets : bool
        ``evidence`` only: ``False`` runs the detection and the merge of the larger sets but
        leaves the conflictive sets of at most ``B`` features as they are, for a caller that
        solves them itself (the online stage, :mod:`.online`); the result is then not
        conflict-free.
    gather_conflictive, gather_free : bool
        ``evidence`` only: the robots solve the conflictive sets of at most ``B`` features
        (``gather_conflictive``, instead of the rule's flood: ``solve_small_sets`` is then
        off) and the conflict-free ones (``gather_free``) at their roots, the robot of each
        set's :func:`~pipeline.consistency.roots.root_of` member (:mod:`pipeline.consistency.
        roots`: bundles up a tree, the cut
        links down; the online stage's step 2b run by the robots). ``stats['roots']``: its
        rounds and sets.

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
    get_rule(resolution)
    _check_options(network_options, protocol)
    fpc = _feature_counts(features_per_camera)
    check_links(links, fpc)
    edges = comm_edges_for(fpc, links, comm_edges)
    n = fpc.shape[0]
    robots, link_index = build_robots(fpc, links)
    network = Network(n, edges, network_options)
    proto = make_protocol(protocol, network, fpc)
    in_batch = _use_batched(engine, network, proto)
    reliable = proto.name == "reliable"
    # a rule that is not fault-tolerant (e.g. the evidence rule) runs on a fault-free network;
    # with faults the fault-tolerant Alg. 1 is used, and stats['resolution'] says so
    rule = rule_for_network(resolution, reliable)
    if network.faulty and not reliable and not rule.fault_tolerant:
        # the paper's protocol as is on a faulty network measures how Alg. 1 breaks; the other
        # rules' floods stalled there (StageStalledError) or failed deep inside (KeyError)
        raise InputError(f"ProtocolOptions(reliable=False) on a faulty network: rule "
                         f"{rule.name!r} needs a lossless network (only 'paper' runs the "
                         "paper's protocol as is, to see it break); leave reliable unset for "
                         "the fault-tolerant protocol, or use resolution='paper'")
    if rule.needs_evidence:
        _equip_evidence(robots, link_index, links, link_weight, keypoints, projections,
                        rule.hook("equip"))
    if bundle_budget is not None:
        if not is_number(bundle_budget) or not np.isfinite(bundle_budget) or int(bundle_budget) != bundle_budget \
                or bundle_budget < 1:
            raise InputError(f"bundle_budget {bundle_budget!r}: give a set size of at least "
                             "1 feature, or None for the default")
        for rb in robots:
            if getattr(rb, "evidence", None) is not None:
                rb.evidence.bundle_budget = int(bundle_budget)
    if not solve_small_sets:
        if not rule.set_lists:
            raise InputError(f"solve_small_sets=False: only a rule with sets of at most B "
                             f"features (evidence) leaves them to the caller, not {rule.name!r}")
        for rb in robots:
            rb.evidence.solve_small = False
    if gather_conflictive or gather_free:
        if not rule.set_lists:
            raise InputError(f"gather_conflictive / gather_free: only a rule with sets of at "
                             f"most B features (evidence) solves them at roots, not "
                             f"{rule.name!r}")
        for rb in robots:
            rb.evidence.gather_conflictive = bool(gather_conflictive)
            rb.evidence.gather_free = bool(gather_free)
    m_total = int(fpc.sum())

    with rounds_bar(f"consistency: {n} robots") as bar:
        if not rule.detection:
            per_iteration, repeated, close_round = _whole_stage(robots, network, in_batch,
                                                                rule, bar), 0, None
        else:
            run_pass = (in_batch and rule.hook("batched")) or rule.hook("simulate")
            per_iteration, repeated, close_round = _loop(robots, network, proto, in_batch,
                                                         run_pass, reliable, m_total, bar)
    result = _collect(fpc, links, robots, link_index, per_iteration, network, proto, repeated,
                      close_round)
    result.stats["resolution"] = rule.name
    stage = per_iteration[0].get("stage", {}) if len(per_iteration) == 1 else {}
    # the evidence rule's (evidence_stage): sets beyond the bundle budget and the rounds of
    # their sync merge
    for key in ("large_sets", "bundle_budget", "merge_rounds"):
        if key in stage:
            result.stats[key] = int(stage[key])
    if "roots" in stage:
        result.stats["roots"] = dict(stage["roots"])
    return result


def _loop(robots, network, proto, in_batch: bool, run_pass, reliable: bool,
          m_total: int, bar) -> tuple[list[dict], int, int | None]:
    """The loop of Prop. 4.5: detection, then resolution, until a detection finds nothing.

    Returns the per-iteration records, the repeated detections and the round of the closing
    (reliable protocol; ``None`` otherwise). ``run_pass``: the resolution rule's pass
    (:mod:`pipeline.consistency.rules`: its batched engine or its per-robot ``simulate``)."""
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
    passes = 0
    redo = False  # a detection repeated after a loss stays in its iteration
    while True:
        passes += 1
        if passes > max_iterations:
            raise RuntimeError(f"conflicts remain after {max_iterations} iterations (Prop. 4.5 bound)")
        if not redo:
            iteration += 1
        redo = False
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
            redo = True
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
                    redo = True
                    continue
                close_round = clo["start_round"]
            rec.update(_delta(c0, network.counters()))
            per_iteration.append(rec)
            break
        on_round = counting(RESOLUTION, iteration)
        res = run_pass(robots, network, proto, iteration, on_round=on_round)
        rec.update(conflictive_sets=res["conflictive_sets"], resolution_rounds=res["rounds"],
                   last_assignment_round=int(max(
                       (int(rb.assigned_round[rb.component >= 0].max(initial=-1)) for rb in robots),
                       default=-1)))
        rec.update(_delta(c0, network.counters()))
        per_iteration.append(rec)
    return per_iteration, repeated, close_round


def _whole_stage(robots, network, in_batch: bool, rule, bar) -> list[dict]:
    """A rule without detection (:mod:`pipeline.consistency.rules`, ``detection=False``): its
    stage on all robots; one record in the per-iteration form of :func:`_loop`."""
    c0 = network.counters()
    bar.set_description_str(f"consistency ({len(robots)} robots): {rule.name}", refresh=False)
    run = (in_batch and rule.hook("stage_batched")) or rule.hook("stage")
    res = run(robots, network, on_round=lambda t: bar.update(1))
    # no detection: the features the rule had to act on are those with a cut link (one pass,
    # counted as an iteration when it cut anything)
    acted = sum(int(np.unique(rb.link_r[~rb.link_alive]).size) for rb in robots)
    # a rule that detects by its own means (``paper-labels``) reports its detection rounds
    det = int(res.get("detection_rounds", 0))
    rec = dict(iteration=1, detection_rounds=det, t_stop=np.zeros(len(robots), dtype=np.int64),
               conflictive_features=acted, conflictive_sets=int(res.get("conflictive_sets", 0)),
               resolution_rounds=int(res["rounds"]) - det, start_round=int(c0.get("round", 0)),
               stage=res)
    rec.update(_delta(c0, network.counters()))
    return [rec]


def _equip_evidence(robots, link_index, links: Links, link_weight, keypoints,
                    projections, equip_robot=equip) -> None:
    """Hand every robot its own evidence (its rows of the inputs only)."""
    from pipeline.matching.link_evidence import ratio_llr

    L = len(links)
    if link_weight is None:
        w = ratio_llr(1.0 - links.quality)
    else:
        try:
            w = np.asarray(link_weight, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(f"link_weight must be numbers, one per link ({exc})") from None
        if w.ndim > 1:  # a table flattened would pair its values with other links
            raise InputError(f"link_weight must be a flat sequence of one number per link, not "
                             f"an array of shape {w.shape}")
        w = w.reshape(-1)
    if w.shape[0] != L:
        raise InputError(f"link_weight has {w.shape[0]} entries for {L} links")
    if np.isnan(w).any():  # the merge rules order links strictly by it: NaN has no place
        k = int(np.flatnonzero(np.isnan(w))[0])
        what = f"quality {links.quality[k]}" if link_weight is None else "link_weight nan"
        raise InputError(f"link {k} ({links.cam_i[k]},{links.feat_i[k]})-({links.cam_j[k]},"
                         f"{links.feat_j[k]}) has {what}: a link's evidence must be a number "
                         "(drop the link, or give it a value)")
    for given, what in ((keypoints, "keypoints"), (projections, "projections")):
        if given is not None and len(given) != len(robots):
            raise InputError(f"{what} has {len(given)} entries for {len(robots)} cameras; give "
                             "one per camera (None for a camera without)" if what ==
                             "projections" else f"{what} has {len(given)} entries for "
                             f"{len(robots)} cameras; give one (m_i, 2) array per camera")
    for rb, li in zip(robots, link_index, strict=True):
        kp = np.zeros((rb.m, 2)) if keypoints is None else keypoints[rb.id]
        P = None if projections is None else projections[rb.id]
        if np.shape(kp) != (rb.m, 2):
            raise InputError(f"keypoints of camera {rb.id} have shape {np.shape(kp)}; expected "
                             f"({rb.m}, 2), one row per feature")
        if P is not None and np.shape(P) != (3, 4):
            raise InputError(f"projection of camera {rb.id} has shape {np.shape(P)}; expected "
                             "(3, 4), or None where unknown")
        # the geometric test's SVD failed on a NaN and never returned on an inf
        for given, what in ((kp, f"keypoints of camera {rb.id}"),
                            (P, f"projection of camera {rb.id}")):
            try:
                finite = given is None or np.isfinite(np.asarray(given, dtype=np.float64))
            except (TypeError, ValueError):
                raise InputError(f"{what} must be numbers") from None
            if not np.all(finite):
                k = tuple(int(x) for x in np.argwhere(~finite)[0])
                raise InputError(f"{what}: a non-finite value at {k} "
                                 f"({np.asarray(given, dtype=np.float64)[k]}); give finite "
                                 "numbers" + (" (None where the pose is unknown)"
                                              if what.startswith("projection") else ""))
        # the geometric test triangulates through finite cameras: with a singular K R (a zero
        # matrix, a camera at infinity) no point fits and every set through it was cut
        if P is not None and np.linalg.matrix_rank(np.asarray(P, dtype=np.float64)[:, :3]) < 3:
            raise InputError(f"projection of camera {rb.id}: its left 3 x 3 block (K R) is "
                             "singular; give the camera's K [R | t] with an invertible K, or "
                             "None where the pose is unknown")
        equip_robot(rb, w[li], kp, P)


def _delta(c0: dict, c1: dict) -> dict:
    return dict(messages=c1["messages"] - c0["messages"], bytes=c1["bytes"] - c0["bytes"])


def _collect(fpc, links: Links, robots: list[Robot], link_index: list[np.ndarray],
             per_iteration: list[dict], network: Network, protocol,
             repeated: int = 0, close_round: int | None = None) -> ConsistencyResult:
    """Read every robot's own log into per-link arrays (reporting only)."""
    survivors = np.array([network.alive(rb.id) for rb in robots], dtype=bool)
    logs = [(li, rb.link_alive, rb.deleted_case, rb.deleted_round, rb.deleted_iteration)
            for rb, li in zip(robots, link_index, strict=True)]
    component = np.concatenate([rb.component for rb in robots]) if robots else np.zeros(0, np.int64)
    track_label = np.concatenate([rb.final_tracks() for rb in robots]) if robots else \
        np.zeros(0, np.int64)
    cnt = network.counters()
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
        protocol=protocol.name,
    )
    if protocol.closing:
        stats["closing_rounds"] = int(sum(p.get("closing_rounds", 0) for p in per_iteration))
        faults.update(close_round=close_round, crashed_after_close={
            i: r for i, r in faults["crashed"].items()
            if close_round is not None and r > close_round
            and not any(i in lost for lost in lost_by)})
    return result_from_logs(links, logs, survivors, component, stats=stats, faults=faults,
                            track_label=track_label)
